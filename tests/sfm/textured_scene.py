"""A small textured scene rendered exactly, for structure-from-motion tests that need no download.

Why not ``fourierf_plugin.synthetic``: its primitives are flat-coloured, and SIFT needs texture. Here three textured
planes form a room corner (floor, back wall, side wall) seen from an arc of cameras; the true poses are known.
"""

from __future__ import annotations

from pathlib import Path

import imageio.v3 as iio
import numpy as np
from scipy.ndimage import gaussian_filter, map_coordinates

TEXELS = 256
# (origin, u axis, v axis): points origin + a u + b v for a, b in [0, 1]
PLANES = (
    (np.array([-2.0, -1.0, 0.0]), np.array([4.0, 0, 0]), np.array([0, 3.0, 0])),  # floor z = 0
    (np.array([-2.0, 2.0, 0.0]), np.array([4.0, 0, 0]), np.array([0, 0, 2.5])),  # back wall y = 2
    (np.array([-2.0, -1.0, 0.0]), np.array([0, 3.0, 0]), np.array([0, 0, 2.5])),  # side wall x = -2
)
TARGET = np.array([0.0, 1.0, 0.6])


def texture(seed: int) -> np.ndarray:
    """[TEXELS, TEXELS, 3] in [0, 1]: blobs at several scales, what SIFT finds and matches well."""
    rng = np.random.default_rng(seed)
    out = np.zeros((TEXELS, TEXELS, 3))
    for sigma, weight in ((1.5, 0.5), (4.0, 1.0), (10.0, 1.0)):
        noise = gaussian_filter(rng.standard_normal((TEXELS, TEXELS, 3)), (sigma, sigma, 0))
        out += weight * noise / noise.std()
    return np.clip(0.5 + 0.15 * out, 0.0, 1.0)


def look_at_opencv(eye: np.ndarray, target: np.ndarray = TARGET) -> np.ndarray:
    """[4, 4] camera-to-world with OpenCV axes (x right, y down, z forward), world +z up."""
    forward = (target - eye) / np.linalg.norm(target - eye)
    right = np.cross(forward, np.array([0.0, 0.0, 1.0]))
    right /= np.linalg.norm(right)
    down = np.cross(forward, right)
    c2w = np.eye(4)
    c2w[:3, :3] = np.stack([right, down, forward], axis=1)
    c2w[:3, 3] = eye
    return c2w


def arc_cameras(n: int, radius: float = 3.6, spread_deg: float = 40.0) -> np.ndarray:
    """``n`` OpenCV camera-to-worlds on an arc in front of the corner, all looking at it."""
    angles = np.radians(np.linspace(-spread_deg / 2, spread_deg / 2, n)) - np.pi / 2 - np.radians(15)
    heights = 1.4 + 0.25 * np.sin(np.linspace(0, np.pi, n))
    eyes = [TARGET + np.array([radius * np.cos(a), radius * np.sin(a), 0.0]) for a in angles]
    return np.stack(
        [look_at_opencv(eye + np.array([0, 0, h - TARGET[2]])) for eye, h in zip(eyes, heights, strict=True)]
    )


def render(c2w: np.ndarray, width: int, height: int, focal: float, textures: list[np.ndarray]) -> np.ndarray:
    """uint8 [H, W, 3] of the planes through a pinhole camera (pixel centres at +0.5)."""
    xs, ys = np.meshgrid(np.arange(width) + 0.5, np.arange(height) + 0.5)
    dirs_cam = np.stack([(xs - width / 2) / focal, (ys - height / 2) / focal, np.ones_like(xs)], axis=-1)
    dirs = dirs_cam.reshape(-1, 3) @ c2w[:3, :3].T
    eye = c2w[:3, 3]
    best_t = np.full(len(dirs), np.inf)
    colour = np.full((len(dirs), 3), 0.5)
    for (origin, u, v), tex in zip(PLANES, textures, strict=True):
        normal = np.cross(u, v)
        denom = dirs @ normal
        with np.errstate(divide="ignore", invalid="ignore"):
            t = ((origin - eye) @ normal) / denom
        hit = eye + t[:, None] * dirs
        a = (hit - origin) @ u / (u @ u)
        b = (hit - origin) @ v / (v @ v)
        ok = (t > 1e-6) & (t < best_t) & (a >= 0) & (a <= 1) & (b >= 0) & (b <= 1)
        coords = np.stack([b[ok] * (TEXELS - 1), a[ok] * (TEXELS - 1)])
        colour[ok] = np.stack([map_coordinates(tex[:, :, c], coords, order=1) for c in range(3)], axis=-1)
        best_t[ok] = t[ok]
    return (colour.reshape(height, width, 3) * 255).round().astype(np.uint8)


def write_photos(folder: Path, n: int = 8, width: int = 160, height: int = 120, focal: float = 130.0) -> np.ndarray:
    """Render ``n`` photos ``view_00.png ...`` into ``folder``; returns their true OpenCV camera-to-worlds."""
    folder.mkdir(parents=True, exist_ok=True)
    textures = [texture(seed) for seed in range(len(PLANES))]
    cameras = arc_cameras(n)
    for i, c2w in enumerate(cameras):
        iio.imwrite(folder / f"view_{i:02d}.png", render(c2w, width, height, focal, textures))
    return cameras


def opengl(c2w_opencv: np.ndarray) -> np.ndarray:
    """The same cameras with OpenGL axes (y up, looking down -z)."""
    out = np.array(c2w_opencv, dtype=np.float64, copy=True)
    out[..., :3, 1:3] *= -1
    return out
