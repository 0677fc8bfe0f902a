"""Tiny scenes written for the tests: an LLFF folder (``poses_bounds.npy`` from known OpenGL poses, and images).

The poses are known OpenGL camera-to-worlds converted back to LLFF's (down, right, back) columns, so a parser's
every step can be checked against ground truth rather than against itself.
"""

from __future__ import annotations

from pathlib import Path

import imageio.v3 as iio
import numpy as np

FULL_H, FULL_W, FULL_FOCAL = 48, 64, 60.0  # full-resolution hwf stored in poses_bounds.npy
SMALL_W, SMALL_H = FULL_W // 8, FULL_H // 8  # images_8: 8x6


def _rotation(rng: np.random.Generator, max_angle: float = 0.3) -> np.ndarray:
    """A proper rotation (det +1) by a small random angle, so the cameras stay forward-facing (looking down -z)."""
    axis = rng.normal(size=3)
    axis /= np.linalg.norm(axis)
    angle = rng.uniform(-max_angle, max_angle)
    k = np.array([[0, -axis[2], axis[1]], [axis[2], 0, -axis[0]], [-axis[1], axis[0], 0]])
    return np.eye(3) + np.sin(angle) * k + (1 - np.cos(angle)) * k @ k


def opengl_poses(n: int, seed: int = 0) -> np.ndarray:
    """[n, 3, 4] forward-facing OpenGL camera-to-worlds: a small rig of cameras near the origin looking down -z."""
    rng = np.random.default_rng(seed)
    c2w = np.zeros((n, 3, 4))
    for i in range(n):
        c2w[i, :, :3] = _rotation(rng)
        c2w[i, :, 3] = rng.uniform(-1.0, 1.0, size=3) * np.array([2.0, 1.5, 0.5]) + np.array([3.0, -1.0, 2.0])
    return c2w


def to_llff_columns(c2w: np.ndarray) -> np.ndarray:
    """Inverse of ``to_opengl``: OpenGL (right, up, back) columns -> LLFF's (down, right, back) = [-c1, c0, c2, t]."""
    return np.concatenate([-c2w[:, :, 1:2], c2w[:, :, 0:1], c2w[:, :, 2:4]], axis=2)


def poses_bounds_array(c2w: np.ndarray, bounds: np.ndarray) -> np.ndarray:
    """N x 17 rows: the LLFF 3x4 pose with the full-resolution [H, W, focal] column, then near and far."""
    n = c2w.shape[0]
    hwf = np.broadcast_to(np.array([FULL_H, FULL_W, FULL_FOCAL], dtype=np.float64)[None, :, None], (n, 3, 1))
    block = np.concatenate([to_llff_columns(c2w), hwf], axis=2)
    return np.concatenate([block.reshape(n, 15), bounds], axis=1)


def default_bounds(n: int) -> np.ndarray:
    near = np.linspace(2.0, 4.0, n)
    return np.stack([near, near * 10.0], axis=1)


def image_pixels(i: int, width: int, height: int) -> np.ndarray:
    """A distinct, deterministic uint8 RGB image per index."""
    rng = np.random.default_rng(1000 + i)
    return rng.integers(0, 256, size=(height, width, 3), dtype=np.uint8)


def write_images(folder: Path, n: int, width: int, height: int) -> None:
    folder.mkdir(parents=True, exist_ok=True)
    for i in range(n):
        iio.imwrite(folder / f"image{i:03d}.png", image_pixels(i, width, height))


def write_llff_scene(
    root: Path,
    n: int = 20,
    seed: int = 0,
    folders: dict[str, int] | None = None,
    c2w: np.ndarray | None = None,
    bounds: np.ndarray | None = None,
) -> Path:
    """An LLFF scene folder: poses_bounds.npy from known OpenGL poses, and images_<k>/ at FULL size // k.

    ``folders`` maps a folder name to its downscale factor (default: images_8 only, 8x6 images).
    """
    root.mkdir(parents=True, exist_ok=True)
    c2w = opengl_poses(n, seed) if c2w is None else c2w
    bounds = default_bounds(n) if bounds is None else bounds
    np.save(root / "poses_bounds.npy", poses_bounds_array(c2w, bounds))
    for name, k in (folders or {"images_8": 8}).items():
        write_images(root / name, n, FULL_W // k, FULL_H // k)
    return root
