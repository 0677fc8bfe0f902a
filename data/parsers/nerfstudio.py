"""nerfstudio's ``transforms.json`` (as ``ns-process-data`` and ``fourierf-process-data`` write it) read into a
:class:`~fourierf_plugin.data.capture.Capture`; the scene is made from it by ``CaptureParser``.

Read as nerfstudio reads it: intrinsics shared at the top or given per frame (a frame's own value wins), one
``camera_model``, distortion ``k1 k2 k3 k4 p1 p2``, file paths relative to the file's folder, optional masks and
split lists, frames in file-name order. ``ply_file_path`` points to sparse points in the frames' world frame
(nerfstudio's writers apply ``applied_transform`` to them too, which is kept only as a record). ``depth_bounds:
[near, far]`` on a frame is our extension: the metric depth range that camera sees, for forward-facing scenes.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass
from pathlib import Path
from typing import Any, ClassVar

import numpy as np

from fourierf_plugin.data.capture import CAMERA_MODELS, DISTORTION_KEYS, Capture, Frame, Intrinsics
from fourierf_plugin.data.parsers.capture_images import variants
from fourierf_plugin.data.parsers.capture_parser import SPLIT_KEYS, CaptureParser, CaptureParserConfig
from fourierf_plugin.data.poses import rotation_problem
from fourierf_plugin.utils.errors import fail
from fourierf_plugin.utils.files import read_json_object

TRANSFORMS_NAME = "transforms.json"
_FIX = "repair transforms.json, or write it again with fourierf-process-data"
_SCENE_FIX = "pass --data pointing at the folder holding transforms.json (or at the JSON file itself)"


def transforms_path(data: Path) -> Path:
    """The JSON to read for ``--data`` (the file itself, or ``transforms.json`` in the folder); a folder without
    one says which parser its contents look like they are for."""
    if data.is_file():
        if data.suffix.lower() != ".json":
            fail(f"--data {data} is a file but not a .json", _SCENE_FIX)
        return data
    if not data.exists():
        fail(f"data folder not found: {data}", _SCENE_FIX)
    path = data / TRANSFORMS_NAME
    if path.is_file():
        return path
    looks_like = [
        (bool(list(data.glob("transforms_*.json"))), "a Blender scene (transforms_<split>.json)", "blender-data"),
        ((data / "poses_bounds.npy").is_file(), "an LLFF scene (poses_bounds.npy)", "llff-data"),
        ((data / "sparse").is_dir(), "a COLMAP project (sparse/)", "colmap-data"),
    ]
    for present, what, parser in looks_like:
        if present:
            fail(f"{data} has no {TRANSFORMS_NAME} but looks like {what}", f"use the {parser} parser for it")
    fail(f"{path} not found", f"{_SCENE_FIX}; fourierf-process-data makes one from a folder of photos")


def _load_json(path: Path) -> dict[str, Any]:
    meta = read_json_object(path, _FIX, "'frames'")
    frames = meta.get("frames")
    if not isinstance(frames, list) or not frames:
        fail(f"{path}: 'frames' must be a non-empty list, got {frames!r:.80}", _FIX)
    return meta


def _number(value: Any, where: str, key: str) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
        fail(f"{where}: {key} must be a finite number, got {value!r:.40}", _FIX)
    return float(value)


def _matrix(value: Any, where: str, key: str, shapes: tuple[tuple[int, int], ...]) -> np.ndarray:
    try:
        matrix = np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError):
        matrix = np.empty(0)
    if matrix.shape not in shapes:
        wanted = " or ".join(f"{r}x{c}" for r, c in shapes)
        fail(f"{where}: {key} must be a {wanted} list of numbers, got {value!r:.80}", _FIX)
    if not np.isfinite(matrix).all():
        fail(f"{where}: {key} has non-finite values (NaN or infinity)", f"fix or remove that frame; {_FIX}")
    return matrix


def _natural_key(text: str) -> list:
    return [int(tok) if tok.isdigit() else tok.lower() for tok in re.split(r"(\d+)", text)]


@dataclass(frozen=True)
class _FrameReader:
    """Reads one frame; a frame's own key wins over the file's shared one."""

    meta: dict[str, Any]
    folder: Path
    source: Path

    def value(self, frame: dict[str, Any], key: str) -> Any:
        return frame[key] if key in frame else self.meta.get(key)

    def size(self, frame: dict[str, Any], where: str, key: str) -> int:
        raw = self.value(frame, key)
        if raw is None:
            fail(f"{where} has no {key} (nor does the file give a shared one)", f"add '{key}' (image size in pixels)")
        size = _number(raw, where, key)
        if size < 1 or size != int(size):
            fail(f"{where}: {key} must be a positive whole number of pixels, got {raw!r}", _FIX)
        return int(size)

    def intrinsics(self, frame: dict[str, Any], where: str) -> Intrinsics:
        width, height = self.size(frame, where, "w"), self.size(frame, where, "h")
        fx_raw, angle = self.value(frame, "fl_x"), self.value(frame, "camera_angle_x")
        if fx_raw is None and angle is None:
            fail(f"{where} has no fl_x (nor does the file give a shared one)", "add 'fl_x' (focal length in pixels)")
        if fx_raw is not None:
            fx = _number(fx_raw, where, "fl_x")
        else:  # instant-ngp and Blender files give the horizontal field of view instead
            angle = _number(angle, where, "camera_angle_x")
            if not 0 < angle < math.pi:
                fail(f"{where}: camera_angle_x must be in (0, pi) radians, got {angle!r}", _FIX)
            fx = 0.5 * width / math.tan(0.5 * angle)
        fy_raw = self.value(frame, "fl_y")
        fy = fx if fy_raw is None else _number(fy_raw, where, "fl_y")
        if not (fx > 0 and fy > 0):
            fail(f"{where}: focal lengths must be > 0, got fl_x={fx:g}, fl_y={fy:g}", _FIX)
        cx_raw, cy_raw = self.value(frame, "cx"), self.value(frame, "cy")
        cx = width / 2 if cx_raw is None else _number(cx_raw, where, "cx")
        cy = height / 2 if cy_raw is None else _number(cy_raw, where, "cy")
        distortion = tuple(
            0.0 if self.value(frame, k) is None else _number(self.value(frame, k), where, k) for k in DISTORTION_KEYS
        )
        model = self.value(frame, "camera_model")
        if model is None:
            model = "OPENCV" if any(distortion) else "PINHOLE"
        if model not in CAMERA_MODELS:
            fail(
                f"{where}: unknown camera_model {model!r}; this parser reads {', '.join(CAMERA_MODELS)}",
                "undistort the photos into one of those models (COLMAP's image_undistorter gives PINHOLE), or "
                "re-run fourierf-process-data",
            )
        named = dict(zip(DISTORTION_KEYS, distortion, strict=True))
        unused = {
            "PINHOLE": DISTORTION_KEYS,
            "SIMPLE_PINHOLE": DISTORTION_KEYS,
            "OPENCV_FISHEYE": ("p1", "p2"),
        }.get(model, ())
        stray = [k for k in unused if named[k] != 0.0]
        if stray:
            fail(
                f"{where}: camera_model {model} has no {', '.join(stray)}, but the file gives "
                + ", ".join(f"{k}={named[k]:g}" for k in stray),
                "set camera_model to the model the coefficients belong to (OPENCV: k1 k2 k3 p1 p2; "
                "OPENCV_FISHEYE: k1..k4), or remove them",
            )
        return Intrinsics(fx, fy, cx, cy, width, height, model, distortion)  # type: ignore[arg-type]

    def file(self, frame: dict[str, Any], where: str, key: str) -> Path:
        name = frame.get(key)
        if not isinstance(name, str) or not name:
            fail(f"{where}: {key} must be a non-empty string, got {name!r:.80}", _FIX)
        path = self.folder / name
        if not path.suffix and not variants(path) and variants(path.with_name(path.name + ".png")):
            path = path.with_name(path.name + ".png")  # a Blender-style path without its extension
        if not variants(path):
            fail(
                f"{where}: {key} {name} not found ({path}, nor a downscaled copy in {path.parent.name}_<k>/)",
                f"restore the file, or fix or remove that frame in {self.source}",
            )
        return path

    def depth_bounds(self, frame: dict[str, Any], where: str) -> tuple[float, float] | None:
        raw = frame.get("depth_bounds")
        if raw is None:
            return None
        if not isinstance(raw, list) or len(raw) != 2:
            fail(f"{where}: depth_bounds must be [near, far], got {raw!r:.80}", _FIX)
        near, far = (_number(v, where, "depth_bounds") for v in raw)
        if not 0 < near < far:
            fail(f"{where}: depth_bounds must satisfy 0 < near < far, got {raw!r}", _FIX)
        return near, far

    def frame(self, frame: Any, index: int) -> Frame:
        where = f"{self.source}, frame {index}"
        if not isinstance(frame, dict) or "file_path" not in frame or "transform_matrix" not in frame:
            fail(f"{where} needs 'file_path' and 'transform_matrix'", _FIX)
        if isinstance(frame["file_path"], str):
            where = f"{where} ({frame['file_path']})"
        image = self.file(frame, where, "file_path")
        c2w = _matrix(frame["transform_matrix"], where, "transform_matrix", ((4, 4), (3, 4)))
        problem = rotation_problem(c2w)
        if problem is not None:
            fail(f"{where}: transform_matrix is not a camera pose: {problem}", f"fix or remove that frame; {_FIX}")
        pose = np.eye(4)
        pose[:3] = c2w[:3]
        return Frame(
            image_path=image,
            camera_to_world=pose,
            intrinsics=self.intrinsics(frame, where),
            mask_path=self.file(frame, where, "mask_path") if frame.get("mask_path") is not None else None,
            depth_bounds=self.depth_bounds(frame, where),
        )


def _read_points(meta: dict[str, Any], folder: Path, source: Path) -> np.ndarray:
    name = meta.get("ply_file_path")
    if name is None:
        return np.zeros((0, 3))
    if not isinstance(name, str) or not (folder / name).is_file():
        fail(
            f"{source}: ply_file_path {name!r} not found",
            f"restore the point file, or remove ply_file_path from {source}",
        )
    import trimesh  # imported lazily: only files with sparse points need it

    path = folder / name
    try:
        loaded = trimesh.load(path, process=False)
    except Exception as err:  # any reader failure on a user's file is a user-fixable problem
        fail(f"cannot read the sparse points {path}: {err}", "write them again (an ASCII or binary PLY of vertices)")
    geometry = loaded.dump(concatenate=True) if isinstance(loaded, trimesh.Scene) else loaded
    vertices = np.asarray(getattr(geometry, "vertices", np.zeros((0, 3))), dtype=np.float64).reshape(-1, 3)
    return vertices[np.isfinite(vertices).all(axis=1)]


def _read_splits(meta: dict[str, Any], source: Path) -> dict[str, list[str]] | None:
    splits = {}
    for key in SPLIT_KEYS:
        names = meta.get(f"{key}_filenames")
        if names is None:
            continue
        if not isinstance(names, list) or not all(isinstance(n, str) for n in names):
            fail(f"{source}: {key}_filenames must be a list of file paths, got {names!r:.80}", _FIX)
        splits[key] = names
    return splits or None


def read_transforms(path: Path) -> Capture:
    """Every frame of a ``transforms.json`` (validated; frames in file-name order) with its points and splits."""
    meta = _load_json(path)
    reader = _FrameReader(meta, path.parent, path)
    frames = [reader.frame(frame, i) for i, frame in enumerate(meta["frames"])]
    seen: dict[str, int] = {}
    for i, frame in enumerate(frames):
        key = str(frame.image_path.resolve())
        if key in seen:
            fail(f"{path}: frames {seen[key]} and {i} both use {frame.image_path}", "remove the duplicate frame")
        seen[key] = i
    order = sorted(range(len(frames)), key=lambda i: _natural_key(str(meta["frames"][i]["file_path"])))
    applied = meta.get("applied_transform")
    return Capture(
        frames=[frames[i] for i in order],
        source=path,
        points=_read_points(meta, path.parent, path),
        splits=_read_splits(meta, path),
        applied_transform=None
        if applied is None
        else _matrix(applied, str(path), "applied_transform", ((3, 4), (4, 4))),
    )


class NerfstudioDataParser(CaptureParser):
    """Reads a nerfstudio ``transforms.json`` (from ``fourierf-process-data`` or ``ns-process-data``)."""

    config: NerfstudioDataParserConfig

    def read_capture(self) -> Capture:
        return read_transforms(transforms_path(Path(self.config.data)))


@dataclass
class NerfstudioDataParserConfig(CaptureParserConfig):
    """nerfstudio data: transforms.json (fourierf-process-data or ns-process-data output) with its photos."""

    _target: ClassVar[type] = NerfstudioDataParser
