"""LLFF forward-facing scenes: ``poses_bounds.npy`` + ``images_<k>/`` photos, with the RegNeRF few-shot rule.

Poses are reordered to OpenGL axes, scaled so the nearest depth bound is 1 / 0.75, and recentred on the average pose
with a proper rotation (det +1; the TensoRF/FourieRF loader uses a reflection there). Rays are later mapped to NDC,
so the box and near/far below are in NDC units.
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from pathlib import Path
from typing import ClassVar

import numpy as np
import torch

from fourierf_plugin.cameras.cameras import Cameras
from fourierf_plugin.data.dataparser_base import (
    DataParser,
    DataParserConfig,
    DataparserOutputs,
    Split,
)
from fourierf_plugin.data.dataparser_transforms import fit_transform
from fourierf_plugin.data.images import load_images
from fourierf_plugin.data.poses import recenter_poses, rotation_problem
from fourierf_plugin.data.scene_effects import SceneDeclaration
from fourierf_plugin.data.view_selection import check_view_counts, explicit_views, regnerf_views, validation_views
from fourierf_plugin.utils.console import warn
from fourierf_plugin.utils.errors import fail

IMAGE_SUFFIXES = (".jpg", ".jpeg", ".png")
NDC_BOX = ((-1.5, -1.67, -1.0), (1.5, 1.67, 1.0))
LLFF_DECLARATION = SceneDeclaration(
    background="none", ray_space="ndc", bounded=False, view_dependent=False, occlusion_regularization=True
)
_SCENE_FIX = "pass --data pointing at an LLFF scene folder (the one holding poses_bounds.npy and images_8/)"


def load_poses_bounds(path: Path) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Raw LLFF poses [N, 3, 4] (down, right, back axes), hwf [N, 3] and bounds [N, 2], validated."""
    if not path.is_file():
        fail(f"{path} not found", _SCENE_FIX)
    try:
        arr = np.load(path, allow_pickle=False)
    except (ValueError, OSError, EOFError) as err:
        fail(
            f"{path} is not a readable .npy array ({err})",
            "re-export poses_bounds.npy (imgs2poses.py) or re-download the scene",
        )
    if arr.ndim != 2 or arr.shape[1] != 17:
        fail(
            f"{path} has shape {arr.shape}; LLFF poses_bounds.npy must be N x 17 "
            "(a 3x5 pose with H, W, focal, then near, far)",
            "re-export poses_bounds.npy with LLFF's imgs2poses.py",
        )
    if arr.shape[0] == 0:
        fail(f"{path} holds no cameras", "re-export poses_bounds.npy with LLFF's imgs2poses.py")
    if arr.dtype == np.bool_ or not (np.issubdtype(arr.dtype, np.floating) or np.issubdtype(arr.dtype, np.integer)):
        fail(
            f"{path} holds {arr.dtype} values, not real numbers", "re-export poses_bounds.npy with LLFF's imgs2poses.py"
        )
    if not np.isfinite(arr).all():
        rows = sorted({int(r) for r in np.argwhere(~np.isfinite(arr))[:, 0]})
        fail(f"{path} has NaN or infinite values in row(s) {rows[:10]}", "re-run pose estimation; the file is corrupt")
    poses = arr[:, :15].reshape(-1, 3, 5).astype(np.float64)
    for row, pose in enumerate(poses):
        problem = rotation_problem(pose[:, :4])
        if problem is not None:
            fail(f"{path}, row {row} (camera {row}): not a camera pose: {problem}", "re-run pose estimation")
    _check_hwf(path, poses[:, :, 4])
    bounds = arr[:, 15:].astype(np.float64)
    if (bounds <= 0).any() or (bounds[:, 0] >= bounds[:, 1]).any():
        fail(f"{path} has depth bounds that are not 0 < near < far", "re-run pose estimation; the bounds are corrupt")
    return poses[:, :, :4], poses[:, :, 4], bounds


def _check_hwf(path: Path, hwf: np.ndarray) -> None:
    """Image size and focal of each row: a size or focal of 0 cannot project (an error); a negative focal mirrors
    the camera (a warning: it trains, likely upside down)."""
    bad = sorted(
        {int(r) for r in np.argwhere(hwf[:, :2] <= 0)[:, 0]} | {int(r) for r in np.argwhere(hwf[:, 2] == 0)[:, 0]}
    )
    if bad:
        fail(
            f"{path} has a height, width or focal length of 0 or below in row(s) {bad[:10]} (H W focal: "
            f"{' '.join(f'{v:g}' for v in hwf[bad[0]])})",
            "re-run pose estimation (imgs2poses.py); those rows are corrupt",
        )
    negative = [int(r) for r in np.argwhere(hwf[:, 2] < 0)[:, 0]]
    if negative:
        warn(
            f"{path} has a negative focal length in row(s) {negative[:10]} ({hwf[negative[0], 2]:g}): those cameras "
            "are mirrored; re-run pose estimation unless that is intended"
        )


def to_opengl(poses: np.ndarray) -> np.ndarray:
    """LLFF's (down, right, back) columns -> OpenGL (right, up, back): [c1, -c0, c2, t]."""
    return np.concatenate([poses[:, :, 1:2], -poses[:, :, 0:1], poses[:, :, 2:4]], axis=2)


def _natural_key(path: Path) -> list:
    return [int(tok) if tok.isdigit() else tok.lower() for tok in re.split(r"(\d+)", path.name)]


def list_images(folder: Path) -> list[Path]:
    return sorted((p for p in folder.iterdir() if p.suffix.lower() in IMAGE_SUFFIXES), key=_natural_key)


def pick_image_folder(data: Path, downscale: int) -> tuple[Path, int]:
    """The folder to read for ``downscale`` and the extra integer factor to apply to it.

    ``images_<k>`` when it exists; otherwise the highest-resolution folder present whose factor divides ``downscale``.
    """
    exact = data / ("images" if downscale == 1 else f"images_{downscale}")
    if exact.is_dir():
        return exact, 1
    present = {1: data / "images"} | {
        int(p.name.split("_")[1]): p for p in data.glob("images_*") if p.is_dir() and p.name.split("_")[1].isdigit()
    }
    usable = sorted(k for k, p in present.items() if p.is_dir() and downscale % k == 0)
    if not usable:
        have = sorted(p.name for p in present.values() if p.is_dir())
        fail(
            f"{data} has no {exact.name}/ folder and no folder to resize it from (found: {have or 'none'})",
            f"add {exact.name}/ (LLFF ships images_4 and images_8), or pick --downscale from the folders present",
        )
    k = usable[0]
    return present[k], downscale // k


class LLFFDataParser(DataParser):
    """Reads an LLFF scene; hold-out test views are every 8th image (llffhold 8)."""

    config: LLFFDataParserConfig

    def declaration(self) -> SceneDeclaration:
        return LLFF_DECLARATION

    def _check_config(self) -> None:
        cfg = self.config
        if cfg.downscale < 1:
            fail(
                f"--downscale must be >= 1, got {cfg.downscale}", "use 8 for images_8 (504x378 on fern), 4 for images_4"
            )
        if cfg.hold_every < 2:
            fail(f"--hold-every must be >= 2, got {cfg.hold_every}", "the LLFF protocol holds out every 8th image")
        check_view_counts(cfg.num_views, cfg.val_views)
        if not cfg.bd_factor > 0:
            fail(f"--bd-factor must be > 0, got {cfg.bd_factor}", "the LLFF default is 0.75")

    def _split_ids(self, split: Split, n: int, source: Path) -> list[int]:
        cfg = self.config
        test = list(range(0, n, cfg.hold_every))
        if split == "test":
            return test
        train = [i for i in range(n) if i % cfg.hold_every]
        if split == "val":
            return validation_views(train, self._split_ids("train", n, source), test, cfg.val_views)
        if cfg.view_ids is not None:
            chosen = explicit_views(cfg.view_ids, n, str(source))
            held = [i for i in chosen if i % cfg.hold_every == 0]
            if held:
                fail(
                    f"--view-ids {held} are hold-out test images (every {cfg.hold_every}th of {source.parent.name})",
                    "choose training ids that are not multiples of the hold-out step",
                )
            return chosen
        if cfg.num_views is not None:
            if cfg.num_views > len(train):
                fail(
                    f"--num-views {cfg.num_views} is more than the {len(train)} training images of {source.parent}",
                    f"use at most {len(train)} views",
                )
            return [train[i] for i in regnerf_views(len(train), cfg.num_views)]
        return train

    def get_outputs(self, split: Split) -> DataparserOutputs:
        self._check_config()
        cfg = self.config
        data = Path(cfg.data)
        if not data.is_dir():
            fail(f"data folder not found: {data}", _SCENE_FIX)
        pb_path = data / "poses_bounds.npy"
        if not pb_path.is_file() and list(data.glob("transforms_*.json")):
            fail(
                f"{data} has transforms_*.json but no poses_bounds.npy: it looks like a Blender scene",
                "use blender-data",
            )
        raw, hwf, bounds = load_poses_bounds(pb_path)
        folder, factor = pick_image_folder(data, cfg.downscale)
        files = list_images(folder)
        if len(files) != raw.shape[0]:
            fail(
                f"{pb_path} has {raw.shape[0]} poses but {folder} has {len(files)} images",
                "the poses and images must match one to one: re-run pose estimation or restore the missing images",
            )
        scale = 1.0 / (bounds.min() * cfg.bd_factor)
        original = to_opengl(raw)
        c2w = original.copy()
        c2w[:, :, 3] *= scale
        c2w = recenter_poses(c2w)
        bounds = bounds * scale

        ids = self._split_ids(split, len(files), pb_path)
        images = load_images([files[i] for i in ids], factor, referenced_by=pb_path)
        height, width = images.shape[1:3]
        focal = hwf[ids, 2] * (width / hwf[ids, 1])
        n = len(ids)
        cameras = Cameras(
            camera_to_worlds=torch.from_numpy(c2w[ids].astype(np.float32)),
            fx=torch.from_numpy(focal.astype(np.float32)),
            fy=torch.from_numpy(focal.astype(np.float32)),
            cx=torch.full((n,), width / 2.0, dtype=torch.float32),
            cy=torch.full((n,), height / 2.0, dtype=torch.float32),
            width=int(width),
            height=int(height),
        )
        return DataparserOutputs(
            images=torch.from_numpy(images),
            cameras=cameras,
            image_names=[files[i].stem for i in ids],
            view_ids=ids,
            scene_box=torch.tensor(NDC_BOX, dtype=torch.float32),
            near=0.0,
            far=1.0,
            scene_name=data.resolve().name,
            source_files=[files[i] for i in ids],
            depth_bounds=(float(bounds.min()), float(bounds.max())),
            dataparser_transform=fit_transform(original, c2w),
        )


@dataclass
class LLFFDataParserConfig(DataParserConfig):
    """LLFF forward-facing scene: poses_bounds.npy and images_<k>/ (NDC rays, hold-out every 8th image)."""

    _target: ClassVar[type] = LLFFDataParser

    downscale: int = 8
    """Downscale factor: reads images_<k>/ (8 gives 504x378 on fern), else resizes the largest folder present."""
    num_views: int | None = None
    """Few-shot: this many training views by the RegNeRF/FreeNeRF rule (evenly spaced over the training images)."""
    view_ids: tuple[int, ...] | None = None
    """Explicit training image indices (0-based, sorted file order); overrides num_views."""
    hold_every: int = 8
    """Every k-th image is a hold-out test view (llffhold 8)."""
    val_views: int = 3
    """Validation views (split "val"): this many unused training images, evenly spaced; the hold-out set if none."""
    bd_factor: float = 0.75
    """Scale the scene so the nearest depth bound becomes 1 / bd_factor."""
