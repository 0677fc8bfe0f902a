"""Camera paths in nerfstudio's ``camera_path.json`` format: written by the viewer's keyframes, read by
``fourierf-render camera-path`` (also a file saved by nerfstudio's own viewer).

The format: ``keyframes`` (each a ``matrix`` of 16 floats, ``fov`` in degrees, ``aspect``), ``camera_path`` (one
entry per frame: ``camera_to_world`` 16 floats of a 4x4 matrix, row-major, OpenGL axes; vertical ``fov`` in
degrees; ``aspect``), ``render_height``, ``render_width``, ``fps``, ``seconds`` and ``camera_type``. Poses are in the
run's world frame, where its training cameras are. Only perspective cameras are rendered.
"""

from __future__ import annotations

import json
import math
import os
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import torch

from fourierf_plugin.cameras.camera_paths import interpolate_path
from fourierf_plugin.cameras.cameras import Cameras
from fourierf_plugin.utils.errors import fail

MAX_PATH_BYTES = 64 * 2**20
"""The largest camera_path.json read (a path of 100k frames is ~40 MB): a bigger file is not a camera path."""


@dataclass(frozen=True)
class Keyframe:
    """One camera of a path: OpenGL camera-to-world [3, 4], vertical field of view (degrees), width / height."""

    camera_to_world: np.ndarray
    fov_deg: float
    aspect: float

    def matrix(self) -> list[float]:
        """The 4x4 pose as 16 floats, row-major (nerfstudio's ``matrix`` / ``camera_to_world``)."""
        full = np.eye(4)
        full[:3, :4] = self.camera_to_world
        return [float(v) for v in full.reshape(-1)]


@dataclass(frozen=True)
class CameraPath:
    """What a ``camera_path.json`` renders: one camera per frame, the image size and the frame rate."""

    cameras: Cameras
    fps: float
    width: int
    height: int


def keyframe_cameras(keyframes: Sequence[Keyframe], width: int, height: int) -> Cameras:
    """The keyframes as a camera set of ``width`` x ``height`` pixels (focal from each vertical fov)."""
    c2w = torch.as_tensor(np.stack([k.camera_to_world for k in keyframes]), dtype=torch.float32)
    focal = torch.tensor([0.5 * height / math.tan(math.radians(k.fov_deg) / 2) for k in keyframes])
    n = len(keyframes)
    return Cameras(c2w, focal, focal.clone(), torch.full((n,), width / 2), torch.full((n,), height / 2), width, height)


def path_frames(keyframes: Sequence[Keyframe], n_frames: int, width: int, height: int) -> Cameras:
    """``n_frames`` cameras through the keyframes in order (positions and focal linearly, rotations by slerp), the
    first and last frames the first and last keyframes."""
    if not keyframes:
        raise ValueError("a camera path needs at least one keyframe")
    keys = keyframe_cameras(keyframes, width, height)
    if len(keyframes) == 1 or n_frames == 1:
        index = torch.zeros(max(n_frames, 1), dtype=torch.long)
        return Cameras(keys.camera_to_worlds[index], keys.fx[index], keys.fy[index], keys.cx[index], keys.cy[index],
                       width, height)  # fmt: skip
    transitions = len(keyframes) - 1
    steps = max(1, math.ceil((n_frames - 1) / transitions))
    dense = interpolate_path(keys, steps, order=False)
    pick = torch.round(torch.linspace(0, len(dense) - 1, n_frames)).long()
    return Cameras(dense.camera_to_worlds[pick], dense.fx[pick], dense.fy[pick], dense.cx[pick], dense.cy[pick],
                   width, height)  # fmt: skip


def camera_path_json(keyframes: Sequence[Keyframe], width: int, height: int, fps: float, seconds: float) -> dict:
    """The nerfstudio ``camera_path.json`` content of a path through ``keyframes`` lasting ``seconds``."""
    n_frames = max(1, round(fps * seconds))
    frames = path_frames(keyframes, n_frames, width, height)
    aspect = width / height
    path = []
    for i in range(len(frames)):
        fov = math.degrees(2 * math.atan(0.5 * height / float(frames.fy[i])))
        pose = Keyframe(frames.camera_to_worlds[i].double().numpy(), fov, aspect)
        path.append({"camera_to_world": pose.matrix(), "fov": fov, "aspect": aspect})
    return {
        "keyframes": [{"matrix": k.matrix(), "fov": k.fov_deg, "aspect": k.aspect} for k in keyframes],
        "camera_type": "perspective",
        "render_height": int(height),
        "render_width": int(width),
        "fps": float(fps),
        "seconds": float(seconds),
        "is_cycle": False,
        "smoothness_value": 0.0,
        "camera_path": path,
    }


def fresh_path(folder: Path, stem: str = "camera_path") -> Path:
    """``folder/<stem>.json``, or ``<stem>-2.json``, ``-3`` ... : a name nothing holds yet (never overwritten)."""
    path, n = folder / f"{stem}.json", 2
    while os.path.lexists(path):
        path, n = folder / f"{stem}-{n}.json", n + 1
    return path


def write_camera_path(folder: Path, content: dict, stem: str = "camera_path") -> Path:
    """Write ``content`` under a fresh name in ``folder`` (created) and return the path; never replaces a file."""
    folder.mkdir(parents=True, exist_ok=True)
    text = json.dumps(content, indent=1)
    while True:
        path = fresh_path(folder, stem)
        try:
            with open(path, "x", encoding="utf-8") as handle:  # "x": a file made meanwhile is not replaced
                handle.write(text)
        except FileExistsError:
            continue
        return path


def _number(value: object, what: str, where: Path, low: float = 0.0) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value) or value <= low:
        fail(f"{where}: {what} must be a number > {low:g}, got {value!r}", "fix the file, or save the path again")
    return float(value)


def _pose(entry: object, index: int, where: Path) -> tuple[np.ndarray, float]:
    """One ``camera_path`` entry's camera-to-world [3, 4] and vertical fov (degrees)."""
    if not isinstance(entry, dict) or "camera_to_world" not in entry or "fov" not in entry:
        fail(f"{where}: camera_path[{index}] needs camera_to_world and fov", "save the path again from a viewer")
    matrix = entry["camera_to_world"]
    values = np.asarray(matrix, dtype=object).reshape(-1) if isinstance(matrix, list) else np.array([])
    ok = values.size == 16 and all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in values)
    pose = np.asarray(values, dtype=np.float64).reshape(4, 4) if ok else None
    if pose is None or not np.isfinite(pose).all():
        fail(f"{where}: camera_path[{index}].camera_to_world must be 16 finite numbers (a 4x4 matrix, row-major)",
             "save the path again from a viewer")  # fmt: skip
    rotation = pose[:3, :3]
    if abs(np.linalg.det(rotation)) < 1e-6:
        fail(f"{where}: camera_path[{index}].camera_to_world has no rotation (a singular matrix)",
             "save the path again from a viewer")  # fmt: skip
    fov = _number(entry["fov"], f"camera_path[{index}].fov", where)
    if fov >= 180:
        fail(f"{where}: camera_path[{index}].fov {fov:g} must be below 180 degrees", "use e.g. 50")
    return pose[:3, :4], fov


def read_camera_path(path: Path, max_frames: int = 100_000) -> CameraPath:
    """The frames of a nerfstudio ``camera_path.json`` (one clear error per problem, naming the file)."""
    path = Path(path)
    if not path.is_file():
        fail(f"camera path not found: {path}", "pass a camera_path.json saved by the viewer's render button")
    if path.stat().st_size > MAX_PATH_BYTES:
        fail(f"{path} is {path.stat().st_size / 2**20:.0f} MiB, too large for a camera path", "pass a camera_path.json")
    try:
        content = json.loads(path.read_text(encoding="utf-8"))
    except (UnicodeDecodeError, ValueError, RecursionError) as err:
        fail(f"{path} is not JSON ({err})", "pass a camera_path.json saved by a viewer")
    if not isinstance(content, dict) or not isinstance(content.get("camera_path"), list):
        fail(f"{path} has no camera_path list", "pass a camera_path.json saved by a viewer (nerfstudio's format)")
    entries = content["camera_path"]
    if not 1 <= len(entries) <= max_frames:
        fail(f"{path} holds {len(entries)} frames; a path needs 1 to {max_frames}", "save the path again")
    camera_type = str(content.get("camera_type", "perspective")).lower()
    if camera_type != "perspective":
        fail(f"{path} has camera_type {camera_type!r}: only perspective paths render here",
             "save the path with the perspective camera type")  # fmt: skip
    height = _number(content.get("render_height"), "render_height", path)
    width = _number(content.get("render_width"), "render_width", path)
    if height != int(height) or width != int(width) or max(width, height) > 8192:
        fail(f"{path}: render_width x render_height {width:g} x {height:g} must be whole pixels, at most 8192",
             "use e.g. 800 x 600")  # fmt: skip
    fps = content.get("fps")
    if fps is None and "seconds" in content:
        fps = len(entries) / _number(content["seconds"], "seconds", path)
    fps = _number(24.0 if fps is None else fps, "fps", path)
    poses = [_pose(entry, i, path) for i, entry in enumerate(entries)]
    c2w = torch.as_tensor(np.stack([p for p, _ in poses]), dtype=torch.float32)
    focal = torch.tensor([0.5 * height / math.tan(math.radians(fov) / 2) for _, fov in poses], dtype=torch.float32)
    n, w, h = len(poses), int(width), int(height)
    cameras = Cameras(c2w, focal, focal.clone(), torch.full((n,), w / 2), torch.full((n,), h / 2), w, h)
    return CameraPath(cameras, fps, w, h)
