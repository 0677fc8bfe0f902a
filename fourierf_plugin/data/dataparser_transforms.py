"""The map from a capture's own world frame to the frame a run trains in, kept beside the run.

Parsers normalise poses (turned upright, recentred, scaled) before training, so geometry read out of a field lives in
that normalised frame. The map is written beside the run as nerfstudio's ``dataparser_transforms.json``
(``{"transform": 3x4, "scale": s}``, with p_normalised = s · (R p + t)), so an exported mesh can be taken back to the
frame of the COLMAP model or ``transforms.json`` it came from. Forward-facing runs also record their NDC mapping
(``"ndc"``), since their field is sampled in normalised device coordinates rather than in the normalised frame.
"""

from __future__ import annotations

import json
import os
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

FILE_NAME = "dataparser_transforms.json"
FIT_TOLERANCE = 1e-6
"""How far (relative to the cameras' extent) a fitted transform may miss a camera centre and still count as exact."""


@dataclass(frozen=True)
class DataparserTransform:
    """p_normalised = scale · (transform[:, :3] @ p_capture + transform[:, 3]), nerfstudio's convention."""

    transform: np.ndarray  # [3, 4] float64
    scale: float

    @staticmethod
    def identity() -> DataparserTransform:
        return DataparserTransform(np.eye(4)[:3].copy(), 1.0)

    @property
    def matrix(self) -> np.ndarray:
        """The whole map as one [4, 4] matrix (capture -> normalised)."""
        out = np.eye(4)
        out[:3] = self.scale * np.asarray(self.transform, dtype=np.float64)
        return out

    def to_normalised(self, points: np.ndarray) -> np.ndarray:
        p = np.asarray(points, dtype=np.float64)
        t = np.asarray(self.transform, dtype=np.float64)
        return self.scale * (p @ t[:, :3].T + t[:, 3])

    def to_capture(self, points: np.ndarray) -> np.ndarray:
        """The inverse map: normalised points [N, 3] back into the capture's frame."""
        p = np.asarray(points, dtype=np.float64)
        t = np.asarray(self.transform, dtype=np.float64)
        return np.linalg.solve(t[:, :3], (p / self.scale - t[:, 3]).T).T

    def after(self, first: np.ndarray) -> DataparserTransform:
        """This map preceded by the affine ``first`` ([3, 4] or [4, 4]): from the frame ``first`` starts in."""
        first = np.asarray(first, dtype=np.float64)[:3]
        t = np.asarray(self.transform, dtype=np.float64)
        linear = t[:, :3] @ first[:, :3]
        return DataparserTransform(
            np.concatenate([linear, (t[:, :3] @ first[:, 3] + t[:, 3])[:, None]], axis=1), self.scale
        )

    def as_json(self) -> dict[str, Any]:
        return {"transform": np.asarray(self.transform, dtype=np.float64).tolist(), "scale": float(self.scale)}


@dataclass(frozen=True)
class NdcFrame:
    """LLFF's NDC mapping of a forward-facing run (``cameras.ndc.ndc_rays``): x' = -2f/W · x/z, y' = -2f/H · y/z,
    z' = 1 + 2 near / z, in the normalised frame where the average camera looks down -z."""

    focal: float
    width: int
    height: int
    near: float = 1.0
    far: float | None = None
    """Metric depth beyond which mapped-back geometry is left out (z' = 1 is infinitely far); None keeps it all."""

    def to_metric(self, points: np.ndarray) -> np.ndarray:
        """NDC points [N, 3] (z' < 1) to the normalised metric frame."""
        p = np.asarray(points, dtype=np.float64)
        ax, ay = -2.0 * self.focal / self.width, -2.0 * self.focal / self.height
        with np.errstate(divide="ignore"):
            z = 2.0 * self.near / (p[:, 2] - 1.0)
        return np.stack([p[:, 0] * z / ax, p[:, 1] * z / ay, z], axis=1)

    def to_ndc(self, points: np.ndarray) -> np.ndarray:
        p = np.asarray(points, dtype=np.float64)
        ax, ay = -2.0 * self.focal / self.width, -2.0 * self.focal / self.height
        z = p[:, 2]
        return np.stack([ax * p[:, 0] / z, ay * p[:, 1] / z, 1.0 + 2.0 * self.near / z], axis=1)

    def as_json(self) -> dict[str, Any]:
        return {"focal": self.focal, "width": self.width, "height": self.height, "near": self.near, "far": self.far}


def fit_transform(before: np.ndarray, after: np.ndarray) -> DataparserTransform | None:
    """The transform that took camera-to-worlds ``before`` [N, 3, 4] to ``after`` (one linear map of the world, a
    uniform scale and a shift), recovered from the poses; None when they do not determine it exactly (all centres in
    one place) or no such transform fits them.

    Why from the poses: every parser's normalisation is of this form, so the same fit serves all of them and stays
    right when a normalisation changes.
    """
    before = np.asarray(before, dtype=np.float64)[:, :3, :4]
    after = np.asarray(after, dtype=np.float64)[:, :3, :4]
    maps = after[:, :, :3] @ np.linalg.inv(before[:, :, :3])  # the world's linear map, once per camera
    linear = maps.mean(axis=0)
    if np.abs(maps - linear).max() > FIT_TOLERANCE * max(1.0, float(np.abs(linear).max())):
        return None
    moved = before[:, :, 3] @ linear.T
    centred = moved - moved.mean(axis=0)
    spread = float((centred**2).sum())
    if spread <= 1e-24 * max(1.0, float((moved**2).sum())):
        return None
    target = after[:, :, 3]
    scale = float(((target - target.mean(axis=0)) * centred).sum() / spread)
    if not scale > 0:
        return None
    shift = target.mean(axis=0) - scale * moved.mean(axis=0)
    extent = float(np.abs(target - target.mean(axis=0)).max())
    if np.abs(scale * moved + shift - target).max() > FIT_TOLERANCE * max(extent, 1e-12):
        return None
    return DataparserTransform(np.concatenate([linear, (shift / scale)[:, None]], axis=1), scale)


def write_dataparser_transforms(
    run_dir: Path, transform: DataparserTransform, ndc: NdcFrame | None = None, object_box: Any = None
) -> Path:
    """``run_dir/dataparser_transforms.json`` (a temporary sibling renamed into place)."""
    record = transform.as_json()
    if ndc is not None:
        record["ndc"] = ndc.as_json()
    if object_box is not None:
        record["object_box"] = [[float(v) for v in corner] for corner in object_box]
    path = Path(run_dir) / FILE_NAME
    tmp = path.with_name(f".{FILE_NAME}.tmp-{os.getpid()}")
    tmp.write_text(json.dumps(record, indent=2) + "\n")
    os.replace(tmp, path)
    return path


NDC_FAR_MARGIN = 2.0
"""Geometry of a forward-facing run is kept out to this multiple of the content's far depth bound: the bound is
measured per camera, and the background lies at it."""


def write_run_frame(run_dir: Path, outputs: Any, ray_space: str) -> Path | None:
    """``dataparser_transforms.json`` for a run trained on ``outputs`` (a parser's ``DataparserOutputs``): its
    transform and, for NDC rays, the reference camera's NDC mapping; nothing when the parser does not know it."""
    if outputs.dataparser_transform is None:
        return None
    ndc = None
    if ray_space == "ndc":
        cameras = outputs.cameras
        far = None if outputs.depth_bounds is None else NDC_FAR_MARGIN * float(outputs.depth_bounds[1])
        ndc = NdcFrame(float(cameras.fx[0]), int(cameras.width), int(cameras.height), 1.0, far)
    return write_dataparser_transforms(run_dir, outputs.dataparser_transform, ndc, getattr(outputs, "object_box", None))


@dataclass(frozen=True)
class RunFrame:
    """What a run's ``dataparser_transforms.json`` says."""

    transform: DataparserTransform
    ndc: NdcFrame | None
    path: Path
    object_box: tuple[tuple[float, ...], tuple[float, ...]] | None = None
    """An unbounded scene's object in the normalised frame, where the parser could tell."""


def read_dataparser_transforms(run_dir: Path) -> RunFrame | None:
    """The run's recorded frame, or None when the run has no ``dataparser_transforms.json``; a malformed file is a
    ValueError naming it."""
    path = Path(run_dir) / FILE_NAME
    if not path.is_file():
        return None
    try:
        record = json.loads(path.read_text(encoding="utf-8"))
        transform = np.asarray(record["transform"], dtype=np.float64)
        scale = float(record["scale"])
        ndc = record.get("ndc")
        box = record.get("object_box")
        object_box = None
        if box is not None:
            corners = np.asarray(box, dtype=np.float64)
            if corners.shape != (2, 3) or not np.isfinite(corners).all() or not (corners[0] < corners[1]).all():
                raise ValueError("'object_box' must be [[min x, y, z], [max x, y, z]] with min < max")
            object_box = (tuple(corners[0].tolist()), tuple(corners[1].tolist()))
        frame = None
        if ndc is not None:
            far = ndc.get("far")
            frame = NdcFrame(
                float(ndc["focal"]),
                int(ndc["width"]),
                int(ndc["height"]),
                float(ndc.get("near", 1.0)),
                None if far is None else float(far),
            )
    except (OSError, ValueError, KeyError, TypeError, AttributeError) as err:
        raise ValueError(f"{path} is not a readable dataparser transform ({err})") from err
    if transform.shape != (3, 4) or not np.isfinite(transform).all() or not (np.isfinite(scale) and scale > 0):
        raise ValueError(f"{path} needs a finite 3x4 'transform' and a positive 'scale'")
    if abs(np.linalg.det(transform[:, :3])) < 1e-12:
        raise ValueError(f"{path}: the 'transform' is singular")
    return RunFrame(DataparserTransform(transform, scale), frame, path, object_box)
