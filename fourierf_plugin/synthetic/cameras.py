"""Cameras of a generated dataset: OpenGL look-at matrices on hemisphere spirals, and the rays of their pixels."""

from __future__ import annotations

import math

import numpy as np

from fourierf_plugin.synthetic.primitives import Vec3

SPLITS = ("train", "val", "test")
_GOLDEN_ANGLE = math.pi * (3.0 - math.sqrt(5.0))


def focal_length(width: int, camera_angle_x: float) -> float:
    """The Blender parser's focal length in pixels."""
    return 0.5 * width / math.tan(0.5 * camera_angle_x)


def pixel_rays(
    c2w: np.ndarray, width: int, height: int, camera_angle_x: float, samples_per_pixel: int = 1
) -> tuple[np.ndarray, np.ndarray]:
    """Origins and unit directions [H, W, k*k, 3] on a k x k grid inside each pixel (k = 1: the pixel centre).

    Same conventions as :meth:`Cameras.generate_rays` with the Blender parser's intrinsics (OpenGL, cx = W / 2).
    """
    k = samples_per_pixel
    f = focal_length(width, camera_angle_x)
    offsets = (np.arange(k) + 0.5) / k
    v = np.arange(height)[:, None, None, None] + offsets[None, None, :, None]  # [H, 1, k, 1]
    u = np.arange(width)[None, :, None, None] + offsets[None, None, None, :]  # [1, W, 1, k]
    x = np.broadcast_to((u - width / 2.0) / f, (height, width, k, k))
    y = np.broadcast_to(-(v - height / 2.0) / f, (height, width, k, k))
    dirs_cam = np.stack([x, y, -np.ones_like(x)], axis=-1).reshape(height, width, k * k, 3)
    c2w = np.asarray(c2w, dtype=np.float64)
    dirs = dirs_cam @ c2w[:3, :3].T
    dirs /= np.linalg.norm(dirs, axis=-1, keepdims=True)
    return np.broadcast_to(c2w[:3, 3], dirs.shape), dirs


def look_at(eye: np.ndarray, target: Vec3 = (0.0, 0.0, 0.0), up: Vec3 = (0.0, 0.0, 1.0)) -> np.ndarray:
    """4x4 OpenGL camera-to-world (x right, y up, looking down -z) at ``eye`` looking at ``target``.

    A float64 numpy twin of :func:`fourierf_plugin.cameras.camera_paths.look_at` (float32 torch [3, 4]): the
    generator writes these matrices into transforms JSON, where exact orthonormality matters.
    """
    eye = np.asarray(eye, dtype=np.float64)
    z = eye - np.asarray(target, dtype=np.float64)
    z /= np.linalg.norm(z)
    x = np.cross(up, z)
    if np.linalg.norm(x) < 1e-9:
        raise ValueError("look_at: the viewing direction is parallel to up")
    x /= np.linalg.norm(x)
    c2w = np.eye(4)
    c2w[:3, 0], c2w[:3, 1], c2w[:3, 2], c2w[:3, 3] = x, np.cross(z, x), z, eye
    return c2w


def hemisphere_cameras(
    n: int,
    radius: float = 4.0,
    phase: float = 0.0,
    min_elevation_deg: float = 10.0,
    max_elevation_deg: float = 80.0,
) -> np.ndarray:
    """[n, 4, 4] cameras on a golden-angle spiral over the upper hemisphere band, all looking at the origin.

    Heights are evenly spaced in sin(elevation), so the views cover the band's area evenly; ``phase`` turns the
    spiral about z (different phases give different views for the same ``n``).
    """
    lo, hi = math.sin(math.radians(min_elevation_deg)), math.sin(math.radians(max_elevation_deg))
    i = np.arange(n)
    z = lo + (hi - lo) * (i + 0.5) / n
    azimuth = phase + i * _GOLDEN_ANGLE
    ring = np.sqrt(1.0 - z**2)
    eyes = radius * np.stack([ring * np.cos(azimuth), ring * np.sin(azimuth), z], axis=1)
    return np.stack([look_at(e) for e in eyes]) if n else np.zeros((0, 4, 4))


def split_cameras(n_train: int, n_val: int, n_test: int, radius: float = 4.0, seed: int = 0) -> dict[str, np.ndarray]:
    """Train/val/test cameras: one spiral per split, each turned by its own seeded phase, so the splits differ."""
    phases = np.random.default_rng(seed).uniform(0.0, 2.0 * math.pi, size=3)
    counts = {"train": n_train, "val": n_val, "test": n_test}
    return {s: hemisphere_cameras(counts[s], radius, float(p)) for s, p in zip(SPLITS, phases, strict=True)}
