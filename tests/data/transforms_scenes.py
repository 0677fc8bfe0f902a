"""Tiny nerfstudio ``transforms.json`` scenes written for the tests: a ring of cameras looking in at the origin (an
object capture) or a forward-facing rig, 8x6 PNGs, with every field variant a test asks for.

Poses, intrinsics and points are known, so the parser's every step can be checked against ground truth.
"""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any

import imageio.v3 as iio
import numpy as np

from fourierf_plugin.cameras.camera_paths import look_at
from tests.scenes import image_pixels, opengl_poses

WIDTH, HEIGHT, FOCAL = 8, 6, 6.0


def homogeneous(c2w: np.ndarray) -> np.ndarray:
    out = np.tile(np.eye(4), (c2w.shape[0], 1, 1))
    out[:, :3, :4] = c2w[:, :3, :4]
    return out


def ring_c2w(n: int, radius: float = 4.0, height: float = 1.0, centre: tuple[float, ...] = (0, 0, 0)) -> np.ndarray:
    """[n, 4, 4] cameras evenly on a horizontal circle about ``centre``, each looking at it, z up."""
    poses = []
    for i in range(n):
        a = 2 * math.pi * i / n
        eye = np.asarray(centre, dtype=np.float64) + np.array([radius * math.cos(a), radius * math.sin(a), height])
        poses.append(look_at(eye.tolist(), list(centre)).double().numpy())
    return homogeneous(np.stack(poses))


def rig_c2w(n: int, seed: int = 0) -> np.ndarray:
    """[n, 4, 4] forward-facing cameras (tests.scenes' LLFF rig): near one another, all looking down -z."""
    return homogeneous(opengl_poses(n, seed))


def rgba_pixels(i: int, width: int, height: int) -> np.ndarray:
    alpha = np.full((height, width, 1), 255, dtype=np.uint8)
    alpha[0, 0] = 0
    return np.concatenate([image_pixels(i, width, height), alpha], axis=2)


def write_image(path: Path, i: int, width: int = WIDTH, height: int = HEIGHT, alpha: bool = False) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    iio.imwrite(path, rgba_pixels(i, width, height) if alpha else image_pixels(i, width, height))


def write_ply(path: Path, points: np.ndarray) -> None:
    """An ASCII PLY of vertices, as nerfstudio's writers make it."""
    header = ["ply", "format ascii 1.0", f"element vertex {len(points)}"]
    header += [f"property float {axis}" for axis in "xyz"] + ["end_header"]
    path.write_text("\n".join(header + [" ".join(f"{v:.8f}" for v in p) for p in points]) + "\n")


def write_scene(
    root: Path,
    c2w: np.ndarray,
    meta: dict[str, Any] | None = None,
    frames: dict[int, dict[str, Any]] | None = None,
    shared: bool = True,
    alpha: bool = False,
    points: np.ndarray | None = None,
    image_names: list[str] | None = None,
) -> Path:
    """A scene folder: ``images/<name>.png`` (8x6) and ``transforms.json`` with shared intrinsics (``shared``) or
    the same ones on every frame; ``meta`` and ``frames`` (index -> keys) add or replace keys. Returns ``root``."""
    root.mkdir(parents=True, exist_ok=True)
    names = image_names or [f"frame_{i:05d}.png" for i in range(len(c2w))]
    intrinsics = {"fl_x": FOCAL, "fl_y": FOCAL, "cx": WIDTH / 2, "cy": HEIGHT / 2, "w": WIDTH, "h": HEIGHT}
    entries = []
    for i, (name, pose) in enumerate(zip(names, c2w, strict=True)):
        write_image(root / "images" / name, i, alpha=alpha)
        entry: dict[str, Any] = {"file_path": f"images/{name}", "transform_matrix": pose.tolist()}
        entry |= {} if shared else intrinsics
        entry |= (frames or {}).get(i, {})
        entries.append(entry)
    document: dict[str, Any] = (intrinsics if shared else {}) | {"frames": entries}
    if points is not None:
        write_ply(root / "sparse_pc.ply", points)
        document["ply_file_path"] = "sparse_pc.ply"
    document |= meta or {}
    (root / "transforms.json").write_text(json.dumps(document, indent=2))
    return root


def edit_transforms(root: Path, change) -> None:
    """Rewrite ``transforms.json`` after ``change(document)`` edits it in place."""
    path = root / "transforms.json"
    document = json.loads(path.read_text())
    change(document)
    path.write_text(json.dumps(document, indent=2))
