"""Feature matching between photos: every pair for small unordered sets, neighbours in time for videos."""

from __future__ import annotations

from pathlib import Path
from types import ModuleType
from typing import Literal

MatchingMode = Literal["auto", "exhaustive", "sequential"]
EXHAUSTIVE_LIMIT = 200
"""Above this many photos, ``auto`` matches sequentially: exhaustive matching grows with the square of the count."""


def resolve_matching(mode: MatchingMode, n_images: int, ordered: bool) -> Literal["exhaustive", "sequential"]:
    """The matcher for ``auto``: sequential for video frames (``ordered``) and very large sets, else exhaustive."""
    if mode != "auto":
        return mode
    return "sequential" if ordered or n_images > EXHAUSTIVE_LIMIT else "exhaustive"


def match_features(
    pycolmap: ModuleType, database: Path, method: Literal["exhaustive", "sequential"], overlap: int = 10
) -> None:
    """Match and geometrically verify the features in ``database``; ``overlap``: sequential's neighbour count."""
    if method == "exhaustive":
        pycolmap.match_exhaustive(database, device=pycolmap.Device.cpu)
        return
    pairing = pycolmap.SequentialPairingOptions()
    pairing.overlap = overlap
    pycolmap.match_sequential(database, pairing_options=pairing, device=pycolmap.Device.cpu)
