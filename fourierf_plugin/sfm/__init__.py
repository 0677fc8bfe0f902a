"""Structure-from-motion on the user's photos through ``pycolmap`` (an optional extra), on the CPU.

Why in Python: nerfstudio's ``ns-process-data`` needs the COLMAP binary installed separately, a frequent stumbling
block; ``pycolmap`` wheels bring COLMAP's SIFT, matching and incremental mapping with nothing to compile.

One module per job: ``colmap_library`` (importing pycolmap, or one clear error naming the extra), ``photos`` (input
photos: listing, copies, downscaled folders), ``video`` (evenly spaced frames of a clip), ``features`` (SIFT),
``matching`` (exhaustive or sequential), ``mapping`` (incremental mapping, the largest model), ``alignment``
(similarity alignment of two sets of cameras, for checking poses), ``progress`` (one display line per stage) and
``pipeline`` (the stages in order). Nothing here is imported by training.
"""
