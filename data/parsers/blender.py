"""NeRF-synthetic ("Blender") scenes: ``transforms_{split}.json`` + RGBA renders, with few-shot view selection."""

from __future__ import annotations

import math
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
from fourierf_plugin.data.dataparser_transforms import DataparserTransform
from fourierf_plugin.data.images import load_images
from fourierf_plugin.data.poses import rotation_problem
from fourierf_plugin.data.scene_effects import SceneDeclaration
from fourierf_plugin.data.view_selection import explicit_views, kmeans_views
from fourierf_plugin.utils.console import warn
from fourierf_plugin.utils.errors import fail
from fourierf_plugin.utils.files import read_json_object

_SCENE_FIX = "pass --data pointing at a NeRF-synthetic scene folder (the one holding transforms_train.json)"


@dataclass(frozen=True)
class _Transforms:
    """The parts of one ``transforms_{split}.json`` that the parser uses, already validated."""

    path: Path
    camera_angle_x: float
    file_paths: list[str]
    matrices: np.ndarray  # [N, 4, 4] float64


def _check_folder(data: Path, split: str) -> Path:
    """The split's JSON, or a UserError that says what the folder looks like instead."""
    if not data.exists():
        fail(f"data folder not found: {data}", _SCENE_FIX)
    if not data.is_dir():
        fail(f"--data {data} is a file, not a scene folder", _SCENE_FIX)
    path = data / f"transforms_{split}.json"
    if path.is_file():
        return path
    present = sorted(p.name for p in data.glob("transforms_*.json"))
    if present:
        fail(
            f"{path} not found (the folder has {', '.join(present)})",
            f"add transforms_{split}.json, or use a complete NeRF-synthetic scene",
        )
    if (data / "poses_bounds.npy").is_file():
        fail(
            f"{data} is not a Blender scene: it has no transforms_*.json but has poses_bounds.npy, "
            "so it looks like an LLFF scene",
            "use the llff-data parser for it",
        )
    fail(f"{data} is not a Blender scene: no transforms_*.json in it", _SCENE_FIX)


def _read_transforms(path: Path) -> _Transforms:
    """Parse and validate a transforms JSON; every defect names the file and, where it helps, the frame."""
    fix = "repair the file, or re-download the scene"
    meta = read_json_object(path, fix, "'camera_angle_x' and 'frames'")
    missing = [key for key in ("camera_angle_x", "frames") if key not in meta]
    if missing:
        fail(f"{path} lacks the key(s) {missing}", f"add {missing} ('camera_angle_x' is the horizontal FOV in radians)")
    angle = meta["camera_angle_x"]
    if isinstance(angle, bool) or not isinstance(angle, (int, float)) or not 0 < angle < math.pi:
        fail(f"{path}: camera_angle_x must be a number in (0, pi) radians, got {angle!r}", fix)
    frames = meta["frames"]
    if not isinstance(frames, list) or not frames:
        fail(f"{path}: 'frames' must be a non-empty list, got {frames!r:.80}", "add at least one frame, or " + fix)
    file_paths: list[str] = []
    matrices = np.empty((len(frames), 4, 4), dtype=np.float64)
    for i, frame in enumerate(frames):
        where = f"{path}, frame {i}"
        if not isinstance(frame, dict) or "file_path" not in frame or "transform_matrix" not in frame:
            fail(f"{where} needs 'file_path' and 'transform_matrix'", fix)
        if not isinstance(frame["file_path"], str) or not frame["file_path"]:
            fail(f"{where}: file_path must be a non-empty string, got {frame['file_path']!r}", fix)
        try:
            matrix = np.asarray(frame["transform_matrix"], dtype=np.float64)
        except (TypeError, ValueError):
            matrix = np.empty(0)
        if matrix.shape != (4, 4):
            fail(f"{where}: transform_matrix must be a 4x4 list of numbers, got {frame['transform_matrix']!r:.80}", fix)
        if not np.isfinite(matrix).all():
            fail(f"{where}: transform_matrix has non-finite values", fix)
        problem = rotation_problem(matrix)
        if problem is not None:
            fail(f"{where}: transform_matrix is not a camera pose: {problem}", f"fix or remove that frame; {fix}")
        if np.abs(matrix).max() > FLOAT32_MAX:
            fail(f"{where}: transform_matrix has values beyond single precision (|x| > 3.4e38)", fix)
        file_paths.append(frame["file_path"])
        matrices[i] = matrix
    _warn_odd_frames(path, file_paths, matrices)
    _warn_ignored_intrinsics(path, meta)
    return _Transforms(path, float(angle), file_paths, matrices)


FLOAT32_MAX = float(np.finfo(np.float32).max)
FAR_CAMERA = 1000.0
"""A camera farther from the cameras' median centre than this many times their median distance from it is named."""
_warned: set[str] = set()


def _warn_once(message: str) -> None:
    """Each split, and each resume check, reads the file again: say a thing once per process."""
    if message not in _warned:
        _warned.add(message)
        warn(message)


INTRINSIC_KEYS = ("fl_x", "fl_y", "cx", "cy", "w", "h")
"""Per-file intrinsics of nerfstudio-style files, which a Blender scene's camera_angle_x and image centre replace."""


def _warn_ignored_intrinsics(path: Path, meta: dict) -> None:
    """Name the intrinsics keys the file gives and this parser reads past (a cx of 1e9 would otherwise pass
    unseen); nerfstudio-data reads them."""
    given = [k for k in INTRINSIC_KEYS if k in meta]
    given += [f"{k} (per frame)" for k in INTRINSIC_KEYS if any(isinstance(f, dict) and k in f for f in meta["frames"])]
    if given:
        values = ", ".join(f"{k} {meta[k]!r:.20}" for k in ("cx", "cy") if k in meta)
        _warn_once(
            f"{path} gives {', '.join(given)}{f' ({values})' if values else ''}, which blender-data ignores: it "
            "takes the focal length from camera_angle_x and the principal point at the image centre; read the "
            "scene with nerfstudio-data to use them"
        )


def _frames(ids: list[int]) -> str:
    return f"frame{'s' if len(ids) > 1 else ''} {', '.join(map(str, ids[:5]))}{' ...' if len(ids) > 5 else ''}"


def _warn_odd_frames(path: Path, file_paths: list[str], matrices: np.ndarray) -> None:
    """Warnings for what loads but is likely a mistake: a bottom row other than (0, 0, 0, 1) (ignored: the top
    3x4 is the pose), one image named by two frames (that view counts twice), a camera far from all others."""
    bottom = [i for i, m in enumerate(matrices) if not np.allclose(m[3], (0.0, 0.0, 0.0, 1.0), atol=1e-6)]
    if bottom:
        _warn_once(
            f"{path}, {_frames(bottom)}: transform_matrix's bottom row is not (0, 0, 0, 1); only its top 3x4 "
            "is used as the camera pose"
        )
    first: dict[str, int] = {}
    for i, name in enumerate(file_paths):
        if name in first:
            _warn_once(f"{path}: frames {first[name]} and {i} both name {name}; that view counts twice")
        first.setdefault(name, i)
    centres = matrices[:, :3, 3]
    distance = np.linalg.norm(centres - np.median(centres, axis=0), axis=1)
    typical = float(np.median(distance))
    far = [i for i, d in enumerate(distance) if d > FAR_CAMERA * max(typical, 1e-9)]
    if len(matrices) > 2 and far:
        _warn_once(
            f"{path}, {_frames(far)}: camera at {centres[far[0]].tolist()}, over {FAR_CAMERA:g} times farther "
            f"from the cameras' centre than the others ({typical:.3g}); check that frame's transform_matrix"
        )


def _image_path(data: Path, file_path: str) -> Path:
    path = data / file_path
    return path.with_name(path.name + ".png") if not path.suffix else path


BLENDER_DECLARATION = SceneDeclaration(
    background="white", ray_space="euclidean", bounded=True, view_dependent=False, occlusion_regularization=False
)
"""Rendered RGBA objects: a white background, euclidean rays in a bounded box; too few views for view dependence."""


class BlenderDataParser(DataParser):
    """Reads a NeRF-synthetic scene: OpenGL camera-to-world matrices and RGBA images composited on white."""

    config: BlenderDataParserConfig

    def declaration(self) -> SceneDeclaration:
        return BLENDER_DECLARATION

    def _check_config(self) -> None:
        cfg = self.config
        if cfg.downscale < 1:
            fail(f"--downscale must be >= 1, got {cfg.downscale}", "use 1 for full resolution, 2 for half, ...")
        if cfg.test_every < 1:
            fail(f"--test-every must be >= 1, got {cfg.test_every}", "use 1 to keep every test view")
        if cfg.num_views is not None and cfg.num_views < 1:
            fail(f"--num-views must be >= 1, got {cfg.num_views}", "omit it to train on every view")
        if not 0 <= cfg.near < cfg.far:
            fail(f"need 0 <= near < far, got near={cfg.near}, far={cfg.far}", "the Blender default is 2 and 6")
        if not cfg.scene_bound > 0:
            fail(f"--scene-bound must be > 0, got {cfg.scene_bound}", "the Blender default is 1.5")

    def _select(self, split: Split, transforms: _Transforms) -> list[int]:
        cfg, total = self.config, len(transforms.file_paths)
        if split != "train":
            return list(range(0, total, cfg.test_every))
        if cfg.view_ids is not None:
            return explicit_views(cfg.view_ids, total, str(transforms.path))
        if cfg.num_views is not None:
            if cfg.num_views > total:
                fail(
                    f"--num-views {cfg.num_views} is more than the {total} frames in {transforms.path}",
                    f"use at most {total} views",
                )
            return kmeans_views(transforms.matrices[:, :3, 3], cfg.num_views, seed=cfg.kmeans_seed)
        return list(range(total))

    def get_outputs(self, split: Split) -> DataparserOutputs:
        self._check_config()
        cfg = self.config
        data = Path(cfg.data)
        transforms = _read_transforms(_check_folder(data, split))
        ids = self._select(split, transforms)
        paths = [_image_path(data, transforms.file_paths[i]) for i in ids]
        images = load_images(paths, cfg.downscale, referenced_by=transforms.path)
        height, width = images.shape[1:3]
        focal = 0.5 * width / math.tan(0.5 * transforms.camera_angle_x)
        n = len(ids)
        cameras = Cameras(
            camera_to_worlds=torch.from_numpy(transforms.matrices[ids, :3, :4].astype(np.float32)),
            fx=torch.full((n,), focal, dtype=torch.float32),
            fy=torch.full((n,), focal, dtype=torch.float32),
            cx=torch.full((n,), width / 2.0, dtype=torch.float32),
            cy=torch.full((n,), height / 2.0, dtype=torch.float32),
            width=int(width),
            height=int(height),
        )
        b = cfg.scene_bound
        return DataparserOutputs(
            images=torch.from_numpy(images),
            cameras=cameras,
            image_names=[Path(transforms.file_paths[i]).stem for i in ids],
            view_ids=ids,
            scene_box=torch.tensor([[-b, -b, -b], [b, b, b]], dtype=torch.float32),
            near=cfg.near,
            far=cfg.far,
            scene_name=data.resolve().name,
            source_files=paths,
            dataparser_transform=DataparserTransform.identity(),  # the poses are used as the files give them
        )


@dataclass
class BlenderDataParserConfig(DataParserConfig):
    """NeRF-synthetic (Blender) scene: transforms_{train,val,test}.json and RGBA PNGs."""

    _target: ClassVar[type] = BlenderDataParser

    downscale: int = 1
    """Integer image downscale factor (the 400 px shared lego with 4 gives 100x100); focal lengths follow."""
    num_views: int | None = None
    """Few-shot: train on this many views picked by seeded k-means on the camera centres (train split only)."""
    view_ids: tuple[int, ...] | None = None
    """Explicit training frame indices into transforms_train.json's frames (r_27 is 27); overrides num_views."""
    kmeans_seed: int = 0
    """Seed of the k-means view selection; the chosen ids are deterministic for a seed."""
    test_every: int = 1
    """Keep every k-th frame of the test and val splits (1 keeps all)."""
    near: float = 2.0
    """Near ray bound (scene units)."""
    far: float = 6.0
    """Far ray bound (scene units)."""
    scene_bound: float = 1.5
    """Half-size of the axis-aligned scene box [-b, b]^3."""
