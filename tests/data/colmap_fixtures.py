"""COLMAP sparse models with known contents, written in COLMAP's text and binary formats by code of the tests' own.

Why: the readers are checked against models whose every number is known (and, where ``pycolmap`` is installed,
against files COLMAP itself wrote); the parser tests need a scene folder with a model and its photos.
"""

from __future__ import annotations

import struct
from dataclasses import dataclass, field
from pathlib import Path

import imageio.v3 as iio
import numpy as np

MODEL_IDS = {"SIMPLE_PINHOLE": 0, "PINHOLE": 1, "SIMPLE_RADIAL": 2, "RADIAL": 3, "OPENCV": 4, "OPENCV_FISHEYE": 5,
             "FULL_OPENCV": 6, "FOV": 7, "SIMPLE_RADIAL_FISHEYE": 8, "RADIAL_FISHEYE": 9, "SIMPLE_FISHEYE": 14,
             "FISHEYE": 15}  # fmt: skip


@dataclass
class Camera:
    camera_id: int
    model: str
    width: int
    height: int
    params: tuple[float, ...]


@dataclass
class Image:
    image_id: int
    rotation: np.ndarray  # world-to-camera, OpenCV axes
    translation: np.ndarray
    camera_id: int
    name: str


@dataclass
class Model:
    cameras: list[Camera]
    images: list[Image]
    points: np.ndarray  # [P, 3]
    colors: np.ndarray  # [P, 3] uint8
    errors: np.ndarray  # [P]
    tracks: list[list[int]] = field(default_factory=list)  # image ids observing each point


def rotation_to_qvec(rot: np.ndarray) -> np.ndarray:
    """(w, x, y, z) of a rotation matrix, w >= 0."""
    w = np.sqrt(max(0.0, 1 + np.trace(rot))) / 2
    x = np.copysign(np.sqrt(max(0.0, 1 + rot[0, 0] - rot[1, 1] - rot[2, 2])) / 2, rot[2, 1] - rot[1, 2])
    y = np.copysign(np.sqrt(max(0.0, 1 - rot[0, 0] + rot[1, 1] - rot[2, 2])) / 2, rot[0, 2] - rot[2, 0])
    z = np.copysign(np.sqrt(max(0.0, 1 - rot[0, 0] - rot[1, 1] + rot[2, 2])) / 2, rot[1, 0] - rot[0, 1])
    q = np.array([w, x, y, z])
    return q / np.linalg.norm(q)


def _look_at_world_to_camera(eye: np.ndarray, target: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """COLMAP's (R, t) of a camera at ``eye`` looking at ``target``, world -y up (COLMAP's usual guess)."""
    forward = (target - eye) / np.linalg.norm(target - eye)
    right = np.cross(forward, np.array([0.0, -1.0, 0.0]))
    right /= np.linalg.norm(right)
    down = np.cross(forward, right)
    rot = np.stack([right, down, forward])  # rows: camera axes in world coordinates
    return rot, -rot @ eye


def make_model(
    names: list[str] | None = None,
    cameras: list[Camera] | None = None,
    n_points: int = 60,
    seed: int = 0,
) -> Model:
    """Cameras on an arc around the origin looking at it, random points near the origin seen by every camera."""
    names = names if names is not None else [f"img_{i:02d}.png" for i in range(5)]
    cameras = (
        cameras
        if cameras is not None
        else [Camera(1, "OPENCV", 64, 48, (60.0, 62.0, 32.5, 23.5, 0.01, -0.002, 1e-4, -2e-4))]
    )
    rng = np.random.default_rng(seed)
    images = []
    for i, name in enumerate(names):
        angle = 0.3 * i
        eye = np.array([4 * np.sin(angle), -0.5 - 0.2 * i, -4 * np.cos(angle)])
        rot, t = _look_at_world_to_camera(eye, rng.normal(0, 0.05, 3))
        images.append(Image(i + 1, rot, t, cameras[i % len(cameras)].camera_id, name))
    points = rng.uniform(-1, 1, (n_points, 3))
    colors = rng.integers(0, 256, (n_points, 3)).astype(np.uint8)
    errors = rng.uniform(0.1, 1.5, n_points)
    tracks = [[im.image_id for im in images] for _ in range(n_points)]
    return Model(cameras, images, points, colors, errors, tracks)


def _points2d(model: Model, image: Image) -> list[tuple[float, float, int]]:
    """Every point this image observes, as (x, y, POINT3D_ID) with ids 1..P (the projections are not needed)."""
    return [(1.0 + j, 2.0 + j, j + 1) for j, track in enumerate(model.tracks) if image.image_id in track]


def _index_in_image(model: Model, image_id: int, point: int) -> int:
    """The position of ``point`` in that image's POINTS2D list (what a track element's POINT2D_IDX names)."""
    return sum(1 for track in model.tracks[:point] if image_id in track)


def write_text(model: Model, folder: Path) -> Path:
    folder.mkdir(parents=True, exist_ok=True)
    lines = ["# Camera list with one line of data per camera:"]
    lines += [f"{c.camera_id} {c.model} {c.width} {c.height} " + " ".join(repr(float(p)) for p in c.params)
              for c in model.cameras]  # fmt: skip
    (folder / "cameras.txt").write_text("\n".join(lines) + "\n")
    lines = ["# Image list with two lines of data per image:", "#   POINTS2D[] as (X, Y, POINT3D_ID)"]
    for im in model.images:
        q = rotation_to_qvec(im.rotation)
        values = " ".join(repr(float(v)) for v in (*q, *im.translation))
        lines.append(f"{im.image_id} {values} {im.camera_id} {im.name}")
        lines.append(" ".join(f"{x} {y} {pid}" for x, y, pid in _points2d(model, im)))
    (folder / "images.txt").write_text("\n".join(lines) + "\n")
    lines = ["# 3D point list with one line of data per point:"]
    for j, (xyz, rgb, err, track) in enumerate(
        zip(model.points, model.colors, model.errors, model.tracks, strict=True)
    ):
        obs = " ".join(f"{image_id} {_index_in_image(model, image_id, j)}" for image_id in track)
        lines.append(f"{j + 1} {' '.join(repr(float(v)) for v in xyz)} {' '.join(str(int(c)) for c in rgb)} "
                     f"{float(err)!r} {obs}")  # fmt: skip
    (folder / "points3D.txt").write_text("\n".join(lines) + "\n")
    return folder


def write_binary(model: Model, folder: Path) -> Path:
    folder.mkdir(parents=True, exist_ok=True)
    out = bytearray(struct.pack("<Q", len(model.cameras)))
    for c in model.cameras:
        out += struct.pack("<iiQQ", c.camera_id, MODEL_IDS[c.model], c.width, c.height)
        out += struct.pack(f"<{len(c.params)}d", *c.params)
    (folder / "cameras.bin").write_bytes(bytes(out))
    out = bytearray(struct.pack("<Q", len(model.images)))
    for im in model.images:
        out += struct.pack("<I7dI", im.image_id, *rotation_to_qvec(im.rotation), *im.translation, im.camera_id)
        out += im.name.encode() + b"\0"
        pts = _points2d(model, im)
        out += struct.pack("<Q", len(pts))
        for x, y, pid in pts:
            out += struct.pack("<ddq", x, y, pid)
    (folder / "images.bin").write_bytes(bytes(out))
    out = bytearray(struct.pack("<Q", len(model.points)))
    for j, (xyz, rgb, err, track) in enumerate(
        zip(model.points, model.colors, model.errors, model.tracks, strict=True)
    ):
        out += struct.pack("<Q3d3Bd", j + 1, *xyz, *rgb, err)
        out += struct.pack("<Q", len(track))
        for image_id in track:
            out += struct.pack("<ii", image_id, _index_in_image(model, image_id, j))
    (folder / "points3D.bin").write_bytes(bytes(out))
    return folder


def write_photos(model: Model, folder: Path) -> Path:
    """A small grey PNG per image, at its camera's size."""
    folder.mkdir(parents=True, exist_ok=True)
    sizes = {c.camera_id: (c.height, c.width) for c in model.cameras}
    for im in model.images:
        iio.imwrite(folder / im.name, np.full((*sizes[im.camera_id], 3), 128, dtype=np.uint8))
    return folder


def write_scene(model: Model, scene: Path, model_path: str = "colmap/sparse/0", binary: bool = True) -> Path:
    """A scene folder: the model at ``model_path`` and its photos in ``images/``."""
    (write_binary if binary else write_text)(model, scene / model_path)
    write_photos(model, scene / "images")
    return scene
