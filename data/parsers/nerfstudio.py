"""nerfstudio's ``transforms.json`` (as ``ns-process-data`` and ``fourierf-process-data`` write it) read into a
:class:`~fourierf_plugin.data.capture.Capture`; the scene is made from it by ``CaptureParser``.

Read as nerfstudio reads it: intrinsics shared at the top or given per frame (a frame's own value wins), one
``camera_model``, distortion ``k1 k2 k3 k4 p1 p2``, file paths relative to the file's folder, optional masks and
split lists, frames in file-name order. ``ply_file_path`` points to sparse points in the frames' world frame
(nerfstudio's writers apply ``applied_transform`` to them too, which is kept only as a record). ``depth_bounds:
[near, far]`` on a frame is our extension: the metric depth range that camera sees, for forward-facing scenes.

instant-ngp's ``transforms.json`` (its ``colmap2nerf.py``) is the same format with a few keys of its own: the field
of view (``camera_angle_x``/``camera_angle_y``) and ``is_fisheye`` are read; the keys that place its scene cube
(``aabb_scale``, ``scale``, ``offset`` ...) and the per-frame ``sharpness`` are named once as ignored: this
parser fits the scene's box to the cameras and sparse points itself. Every frame whose image is missing is listed in
one error (``--skip-missing-images`` trains on the rest); frames naming one photo twice are merged when they agree.
"""

from __future__ import annotations

import math
import os
import re
from dataclasses import dataclass
from pathlib import Path
from typing import Any, ClassVar

import numpy as np

from fourierf_plugin.data.capture import CAMERA_MODELS, DISTORTION_KEYS, Capture, Frame, Intrinsics
from fourierf_plugin.data.parsers.capture_images import variants
from fourierf_plugin.data.parsers.capture_parser import SPLIT_KEYS, CaptureParser, CaptureParserConfig
from fourierf_plugin.data.poses import rotation_problem
from fourierf_plugin.utils.console import get_console, warn
from fourierf_plugin.utils.errors import fail
from fourierf_plugin.utils.files import read_json_object

TRANSFORMS_NAME = "transforms.json"
_FIX = "repair transforms.json, or write it again with fourierf-process-data"
_SCENE_FIX = "pass --data pointing at the folder holding transforms.json (or at the JSON file itself)"
_SKIP_FLAG = "nerfstudio-data --skip-missing-images True"
_SHOWN = 8
"""Names a message lists before "... and N more"."""

NGP_IGNORED = (
    "aabb_scale",
    "aabb",
    "render_aabb",
    "render_aabb_to_local",
    "scale",
    "offset",
    "integer_depth_scale",
    "enable_depth_loading",
    "n_extra_learnable_dims",
    "white_transparent",
    "black_transparent",
)
"""instant-ngp's top-level keys that place and shape its scene cube or its depth and extra inputs: read past, as
the box and scale here come from the cameras and sparse points (``scale``/``offset`` are a similarity, which the
normalisation removes anyway)."""
NGP_IGNORED_PER_FRAME = ("sharpness",)
"""instant-ngp's per-frame keys read past (``sharpness``: colmap2nerf's blur measure of the photo)."""
_SAID: set[str] = set()
"""Notes already printed in this process: a parser is set up several times per run, a note is worth one line."""


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


def _say_once(text: str, warning: bool = False) -> None:
    """Print ``text`` (a note on stdout, or a warning on stderr) the first time this process meets it."""
    if text in _SAID:
        return
    _SAID.add(text)
    if warning:
        warn(text)
    else:
        get_console().print(text, soft_wrap=True, markup=False)


def _listing(items: list[str]) -> str:
    """The first few of ``items``, comma-separated, and how many more there are."""
    shown = ", ".join(items[:_SHOWN])
    return shown + (f" ... and {len(items) - _SHOWN} more" if len(items) > _SHOWN else "")


def _note_ignored_keys(meta: dict[str, Any], source: Path) -> None:
    """One printed line naming the instant-ngp keys of the file that are read past."""
    ignored = [key for key in NGP_IGNORED if key in meta]
    frames = [f for f in meta["frames"] if isinstance(f, dict)]
    ignored += [f"{key} (per frame)" for key in NGP_IGNORED_PER_FRAME if any(key in f for f in frames)]
    if ignored:
        _say_once(
            f"{source}: instant-ngp keys ignored: {', '.join(ignored)} (the scene's box and scale are fitted to "
            "the cameras and sparse points here)"
        )


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
        fy_raw, angle_y = self.value(frame, "fl_y"), self.value(frame, "camera_angle_y")
        if fy_raw is not None:
            fy = _number(fy_raw, where, "fl_y")
        elif angle_y is not None and fx_raw is None:  # instant-ngp: the vertical field of view, when fl_x is absent
            angle_y = _number(angle_y, where, "camera_angle_y")
            if not 0 < angle_y < math.pi:
                fail(f"{where}: camera_angle_y must be in (0, pi) radians, got {angle_y!r}", _FIX)
            fy = 0.5 * height / math.tan(0.5 * angle_y)
        else:
            fy = fx
        if not (fx > 0 and fy > 0):
            fail(f"{where}: focal lengths must be > 0, got fl_x={fx:g}, fl_y={fy:g}", _FIX)
        cx_raw, cy_raw = self.value(frame, "cx"), self.value(frame, "cy")
        cx = width / 2 if cx_raw is None else _number(cx_raw, where, "cx")
        cy = height / 2 if cy_raw is None else _number(cy_raw, where, "cy")
        distortion = tuple(
            0.0 if self.value(frame, k) is None else _number(self.value(frame, k), where, k) for k in DISTORTION_KEYS
        )
        model = self.value(frame, "camera_model")
        fisheye = self.value(frame, "is_fisheye")
        if fisheye is not None and not isinstance(fisheye, bool):
            fail(f"{where}: is_fisheye must be true or false, got {fisheye!r:.40}", _FIX)
        if model is None:
            model = "OPENCV_FISHEYE" if fisheye else "OPENCV" if any(distortion) else "PINHOLE"
        elif fisheye and model != "OPENCV_FISHEYE":
            fail(
                f"{where}: is_fisheye is true (instant-ngp) but camera_model is {model!r}",
                "remove one of the two: camera_model OPENCV_FISHEYE is the fisheye lens (k1..k4)",
            )
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

    def where(self, frame: Any, index: int) -> str:
        """How messages name a frame: the file, its index, and its file_path when it has one."""
        where = f"{self.source}, frame {index}"
        name = frame.get("file_path") if isinstance(frame, dict) else None
        return f"{where} ({name})" if isinstance(name, str) else where

    def path(self, frame: dict[str, Any], where: str, key: str) -> Path:
        """Where ``frame[key]`` points (a Blender-style name without extension gets its ``.png``); not checked."""
        name = frame.get(key)
        if not isinstance(name, str) or not name:
            fail(f"{where}: {key} must be a non-empty string, got {name!r:.80}", _FIX)
        path = self.folder / name
        if not path.suffix and not variants(path) and variants(path.with_name(path.name + ".png")):
            path = path.with_name(path.name + ".png")  # a Blender-style path without its extension
        return path

    def image(self, frame: Any, index: int) -> Path:
        """The frame's image path after checking the frame's shape (present on disk or not)."""
        if not isinstance(frame, dict) or "file_path" not in frame or "transform_matrix" not in frame:
            fail(f"{self.source}, frame {index} needs 'file_path' and 'transform_matrix'", _FIX)
        return self.path(frame, self.where(frame, index), "file_path")

    def file(self, frame: dict[str, Any], where: str, key: str) -> Path:
        path = self.path(frame, where, key)
        name = frame[key]
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

    def frame(self, frame: dict[str, Any], index: int, image: Path) -> Frame:
        """The frame at ``index``, its image (found on disk) at ``image``."""
        where = self.where(frame, index)
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


def _missing_images(images: list[Path], source: Path, skip: bool, meta: dict[str, Any]) -> set[int]:
    """The indices of the frames whose image is on disk in no copy: every one named at once in an error, or, with
    ``skip``, left out with a warning saying how many."""
    missing = [i for i, image in enumerate(images) if not variants(image)]
    if not missing:
        return set()
    n, k = len(images), len(missing)
    names = [f"frame {i} ({meta['frames'][i]['file_path']})" for i in missing]
    folders = sorted({images[i].parent for i in missing})
    looked = f"looked in {_listing([_with_count(f) for f in folders])} and the downscaled copies <folder>_<k>/"
    if k == n:
        fail(
            f"{source}: none of its {n} frames' images is found ({looked}; e.g. {images[missing[0]]})",
            "restore the photos; file_path entries are read relative to the folder holding transforms.json",
        )
    if skip:
        _say_once(
            f"{source}: skipped {k} of {n} frames whose images are missing (--skip-missing-images True): "
            f"{_listing(names)}; training on the other {n - k}",
            warning=True,
        )
        return set(missing)
    if k == 1:
        image = images[missing[0]]
        problem = (
            f"{source}, frame {missing[0]} ({meta['frames'][missing[0]]['file_path']}): file_path not found "
            f"({image}, nor a downscaled copy in {image.parent.name}_<k>/)"
        )
        fix = f"restore the file, pass {_SKIP_FLAG} to train without that frame, or remove it from {source}"
        fail(problem, fix)
    fail(
        f"{source}: {k} of {n} frames name images that are not found: {_listing(names)} ({looked})",
        f"restore the photos, or pass {_SKIP_FLAG} to train on the {n - k} frames whose images are present",
    )


def _with_count(folder: Path) -> str:
    """A folder named with how many images it holds (a hint when frames outnumber the photos)."""
    if not folder.is_dir():
        return f"{folder} (no such folder)"
    count = sum(1 for p in folder.iterdir() if p.suffix.lower() in (".png", ".jpg", ".jpeg"))
    return f"{folder} ({count} images there)"


def _same_camera(a: Frame, b: Frame) -> bool:
    return a.intrinsics == b.intrinsics and bool(np.allclose(a.camera_to_world, b.camera_to_world, atol=1e-6))


def _merge_duplicates(frames: dict[int, Frame], meta: dict[str, Any], source: Path) -> dict[int, Frame]:
    """One frame per photo: frames naming an image again with the same camera are dropped with a warning naming
    them; frames naming it with another camera are one error naming every such pair (which pose is right is not
    known)."""
    first: dict[Path, int] = {}
    repeats: list[tuple[int, int]] = []
    for i, frame in frames.items():
        key = frame.image_path.resolve()
        if key in first:
            repeats.append((first[key], i))
        else:
            first[key] = i
    if not repeats:
        return frames
    pairs = [f"frames {a} and {b} ({meta['frames'][b]['file_path']})" for a, b in repeats]
    conflicting = [p for p, (a, b) in zip(pairs, repeats, strict=True) if not _same_camera(frames[a], frames[b])]
    if conflicting:
        fail(
            f"{source}: {len(conflicting)} photo(s) are named by two frames with different cameras: "
            f"{_listing(conflicting)}",
            "keep one frame per photo (remove the others from frames)",
        )
    _say_once(
        f"{source}: {len(repeats)} frame(s) repeat a photo with the same camera and are used once: {_listing(pairs)}",
        warning=True,
    )
    dropped = {b for _, b in repeats}
    return {i: frame for i, frame in frames.items() if i not in dropped}


def _drop_from_splits(splits: dict[str, list[str]] | None, folder: Path, skipped: list[str]) -> dict | None:
    """The split lists without the file paths of skipped frames."""
    if splits is None or not skipped:
        return splits
    gone = {os.path.normpath(folder / name) for name in skipped}
    return {key: [n for n in names if os.path.normpath(folder / n) not in gone] for key, names in splits.items()}


def read_transforms(path: Path, skip_missing_images: bool = False) -> Capture:
    """Every frame of a ``transforms.json`` (validated; frames in file-name order) with its points and splits.

    ``skip_missing_images``: frames whose photo is missing are left out (with a warning) instead of failing."""
    meta = _load_json(path)
    _note_ignored_keys(meta, path)
    reader = _FrameReader(meta, path.parent, path)
    images = [reader.image(frame, i) for i, frame in enumerate(meta["frames"])]
    skipped = _missing_images(images, path, skip_missing_images, meta)
    frames = {i: reader.frame(frame, i, images[i]) for i, frame in enumerate(meta["frames"]) if i not in skipped}
    frames = _merge_duplicates(frames, meta, path)
    order = sorted(frames, key=lambda i: _natural_key(str(meta["frames"][i]["file_path"])))
    splits = _drop_from_splits(
        _read_splits(meta, path), path.parent, [meta["frames"][i]["file_path"] for i in sorted(skipped)]
    )
    applied = meta.get("applied_transform")
    return Capture(
        frames=[frames[i] for i in order],
        source=path,
        points=_read_points(meta, path.parent, path),
        splits=splits,
        applied_transform=None
        if applied is None
        else _matrix(applied, str(path), "applied_transform", ((3, 4), (4, 4))),
    )


class NerfstudioDataParser(CaptureParser):
    """Reads a nerfstudio ``transforms.json`` (from ``fourierf-process-data`` or ``ns-process-data``)."""

    config: NerfstudioDataParserConfig

    def read_capture(self) -> Capture:
        return read_transforms(transforms_path(Path(self.config.data)), self.config.skip_missing_images)


@dataclass
class NerfstudioDataParserConfig(CaptureParserConfig):
    """nerfstudio data: transforms.json (fourierf-process-data or ns-process-data output) with its photos."""

    _target: ClassVar[type] = NerfstudioDataParser
    skip_missing_images: bool = False
    """Train on the frames whose photos are present, leaving out (and counting) those whose image is missing,
    instead of stopping with the list of missing ones."""
