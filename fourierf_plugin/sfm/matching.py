"""Feature matching between photos: every pair for small unordered sets, neighbours in time for videos."""

from __future__ import annotations

import math
from pathlib import Path
from types import ModuleType
from typing import Literal

MatchingMode = Literal["auto", "exhaustive", "sequential"]
EXHAUSTIVE_LIMIT = 200
"""Above this many photos, ``auto`` matches sequentially: exhaustive matching grows with the square of the count."""
SEQUENTIAL_OVERLAP = 10
"""Sequential matching pairs each frame with this many following ones (and, quadratically, frames 2^k later)."""


def resolve_matching(mode: MatchingMode, n_images: int, ordered: bool) -> Literal["exhaustive", "sequential"]:
    """The matcher for ``auto``: sequential for video frames (``ordered``) and very large sets, else exhaustive."""
    if mode != "auto":
        return mode
    return "sequential" if ordered or n_images > EXHAUSTIVE_LIMIT else "exhaustive"


def exhaustive_block_size(n_images: int) -> int:
    """Photos per block of exhaustive matching: COLMAP writes each block's pairs in one transaction, so blocks of
    about a fifth of the photos let the progress count move a dozen times or more (10 to 50 photos a block)."""
    return max(10, min(50, math.ceil(n_images / 5)))


def pair_count(method: Literal["exhaustive", "sequential"], n_images: int, overlap: int = SEQUENTIAL_OVERLAP) -> int:
    """The image pairs a matcher compares (COLMAP's pair generators), the total of the matching progress."""
    if method == "exhaustive":
        return n_images * (n_images - 1) // 2
    pairs = set()
    for first in range(n_images):
        for k in range(overlap):
            for second in (first + k + 1, first + (1 << k)):  # the neighbours, and quadratic overlap's 2^k
                if second < n_images:
                    pairs.add((first, second))
    return len(pairs)


def match_features(
    pycolmap: ModuleType,
    database: Path,
    method: Literal["exhaustive", "sequential"],
    overlap: int = SEQUENTIAL_OVERLAP,
    threads: int | None = None,
    n_images: int | None = None,
) -> None:
    """Match and geometrically verify the features in ``database``; ``overlap``: sequential's neighbour count;
    ``threads``: CPU threads (None: all cores); ``n_images`` sizes exhaustive matching's blocks for progress."""
    matching = pycolmap.FeatureMatchingOptions()
    matching.use_gpu = False
    if threads is not None:
        matching.num_threads = threads
    if method == "exhaustive":
        pairing = pycolmap.ExhaustivePairingOptions()
        if n_images is not None:
            pairing.block_size = exhaustive_block_size(n_images)
        pycolmap.match_exhaustive(
            database, matching_options=matching, pairing_options=pairing, device=pycolmap.Device.cpu
        )
        return
    pairing = pycolmap.SequentialPairingOptions()
    pairing.overlap = overlap
    if threads is not None:
        pairing.num_threads = threads
    pycolmap.match_sequential(database, matching_options=matching, pairing_options=pairing, device=pycolmap.Device.cpu)
