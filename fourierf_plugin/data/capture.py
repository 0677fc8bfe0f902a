"""A photo capture as structure-from-motion describes it, before any normalisation: the common form of
nerfstudio's ``transforms.json`` and a COLMAP sparse model.

Both the ``nerfstudio-data`` and the ``colmap-data`` parsers read their files into a :class:`Capture`; one piece of
code (``data/parsers/capture_parser.py``) turns a capture into a scene (normalised poses, box, splits, effects).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

# The lens models and the coefficient order (also that of ``Intrinsics.distortion``) are defined once, where rays
# are undistorted; re-exported here for the parsers.
from fourierf_plugin.cameras.distortion import CAMERA_MODELS, DISTORTION_KEYS, CameraModel

__all__ = ["CAMERA_MODELS", "DISTORTION_KEYS", "CameraModel", "Capture", "Frame", "Intrinsics"]


@dataclass(frozen=True)
class Intrinsics:
    """One camera's intrinsics in pixels of its full-resolution image (pixel centres at +0.5).

    ``distortion`` holds (k1, k2, k3, k4, p1, p2): OPENCV uses k1 k2 (k3) p1 p2 (radial-tangential), OPENCV_FISHEYE
    uses k1..k4 (equidistant); PINHOLE and SIMPLE_PINHOLE have all zeros.
    """

    fx: float
    fy: float
    cx: float
    cy: float
    width: int
    height: int
    camera_model: CameraModel = "PINHOLE"
    distortion: tuple[float, float, float, float, float, float] = (0.0, 0.0, 0.0, 0.0, 0.0, 0.0)


@dataclass(frozen=True)
class Frame:
    """One registered photo: its file, its camera-to-world (OpenGL: x right, y up, looking down -z) and intrinsics."""

    image_path: Path
    camera_to_world: np.ndarray  # [4, 4] float64, OpenGL convention, in the capture's world frame
    intrinsics: Intrinsics
    mask_path: Path | None = None
    depth_bounds: tuple[float, float] | None = None  # metric (near, far) of what this camera sees, when known


@dataclass
class Capture:
    """Registered photos of one scene, in the world frame of the file they came from.

    ``points`` are sparse structure-from-motion points [P, 3] in the same world frame (empty when unknown);
    ``splits`` are explicit file names per split (nerfstudio's ``train_filenames`` ...), None when the file has none.
    ``source`` is the file the capture was read from, for error messages.
    """

    frames: list[Frame]
    source: Path
    points: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))
    splits: dict[str, list[str]] | None = None
    applied_transform: np.ndarray | None = None  # [3, 4] or [4, 4]: what the writer applied to COLMAP's world frame
