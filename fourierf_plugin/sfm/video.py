"""Evenly spaced frames of a video clip, read through imageio (MP4 needs its ffmpeg plugin; GIF needs nothing)."""

from __future__ import annotations

import warnings
from pathlib import Path

import imageio.v3 as iio
import numpy as np

from fourierf_plugin.utils.console import warn
from fourierf_plugin.utils.errors import fail

_VIDEO_FIX = (
    "check that the file is a video imageio can read; MP4, MOV and AVI need the ffmpeg plugin: "
    "pip install '.[video]' (imageio-ffmpeg)"
)


def evenly_spaced(total: int, count: int) -> list[int]:
    """``count`` frame indices spread over ``total`` frames, first and last included (all frames when fewer)."""
    if count >= total:
        return list(range(total))
    if count == 1:
        return [0]
    return sorted({round(float(i)) for i in np.linspace(0, total - 1, count)})


def _frames(video: Path):
    try:
        with warnings.catch_warnings():  # imageio tries every plugin on an unknown file; old ones warn as they load
            warnings.simplefilter("ignore", DeprecationWarning)
            yield from iio.imiter(video)
    except Exception as err:  # imageio raises many kinds for unreadable or unsupported files
        fail(f"cannot read the video {video} ({type(err).__name__}: {err})", _VIDEO_FIX)


def count_frames(video: Path) -> int:
    """The number of frames, from the container's metadata when it gives one, else by decoding the clip once."""
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", DeprecationWarning)
            props = iio.improps(video)
    except Exception:  # fall back to decoding, which reports a real problem with the file
        props = None
    if props is not None and props.is_batch and isinstance(props.n_images, int) and props.n_images > 0:
        return props.n_images
    return sum(1 for _ in _frames(video))


def extract_frames(video: Path, output_dir: Path, num_frames: int) -> list[Path]:
    """Save ``num_frames`` evenly spaced frames of ``video`` as ``frame_00001.png ...`` in ``output_dir``."""
    video = Path(video)
    if not video.is_file():
        fail(f"video not found: {video}", "pass --data pointing at a video file (e.g. clip.mp4)")
    if num_frames < 3:
        fail(f"--num-frames must be at least 3, got {num_frames}", "use 50-300 frames for a typical clip")
    total = count_frames(video)
    if total == 0:
        fail(f"the video {video} has no frames", _VIDEO_FIX)
    wanted = evenly_spaced(total, num_frames)
    if len(wanted) < num_frames:
        warn(f"{video} has only {total} frames: using all of them instead of {num_frames}")
    output_dir.mkdir(parents=True, exist_ok=True)
    keep = set(wanted)
    written = []
    for index, frame in enumerate(_frames(video)):
        if index in keep:
            rgb = np.asarray(frame)
            rgb = rgb[:, :, :3] if rgb.ndim == 3 else rgb
            path = output_dir / f"frame_{len(written) + 1:05d}.png"
            iio.imwrite(path, rgb)
            written.append(path)
        if len(written) == len(wanted):
            break
    if len(written) < len(wanted):
        fail(f"the video {video} ended after {index + 1} of {total} frames (truncated?)", _VIDEO_FIX)
    return written
