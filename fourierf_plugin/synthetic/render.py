"""Exact ray casting of a scene: nearest hits, their colour, and one camera's straight-alpha RGBA image.

The renderer simulates only what a ground-truth scene needs: coverage (alpha) and the diffuse albedo (a primitive's
flat colour, or its texture at the hit point); Lambert shading from one directional light is added only when asked.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

import numpy as np

from fourierf_plugin.synthetic.cameras import pixel_rays
from fourierf_plugin.synthetic.scene import SceneSpec

Shading = Literal["none", "lambert"]

_CHUNK_RAYS = 1 << 18  # rays intersected at once: bounds memory at large sizes with supersampling


@dataclass(frozen=True)
class RayHits:
    """Nearest hits of a batch of rays: ``t`` ([N], inf on a miss), ``index`` ([N], -1 on a miss), ``normal``, and
    the hit ``point`` ([N, 3], NaN on a miss)."""

    t: np.ndarray
    index: np.ndarray
    normal: np.ndarray
    point: np.ndarray

    @property
    def hit(self) -> np.ndarray:
        return self.index >= 0


def intersect_scene(spec: SceneSpec, origins: np.ndarray, directions: np.ndarray) -> RayHits:
    """Exact nearest intersection of rays ``o + t d`` ([N, 3] each) with the scene's primitives."""
    origins = np.asarray(origins, dtype=np.float64).reshape(-1, 3)
    directions = np.asarray(directions, dtype=np.float64).reshape(-1, 3)
    n = len(origins)
    best_t = np.full(n, np.inf)
    index = np.full(n, -1, dtype=np.int64)
    normal = np.zeros((n, 3))
    for i, prim in enumerate(spec.primitives):
        t, nrm = prim.intersect(origins, directions)
        closer = t < best_t
        best_t[closer], index[closer], normal[closer] = t[closer], i, nrm[closer]
    point = np.full((n, 3), np.nan)
    hit = index >= 0
    point[hit] = origins[hit] + best_t[hit, None] * directions[hit]
    return RayHits(best_t, index, normal, point)


def shade(spec: SceneSpec, hits: RayHits, directions: np.ndarray, shading: Shading = "none") -> np.ndarray:
    """Colour [N, 3] of each ray (0 on a miss): the albedo, times the Lambert term when ``shading="lambert"``."""
    albedo = np.array([p.color for p in spec.primitives] + [(0.0, 0.0, 0.0)])
    rgb = albedo[hits.index]  # index -1 picks the trailing black row
    for i, prim in enumerate(spec.primitives):
        mine = hits.index == i
        if getattr(prim, "texture", None) is not None and mine.any():
            rgb[mine] = prim.color_at(hits.point[mine], hits.normal[mine])
    if shading == "none":
        return rgb
    if shading != "lambert":
        raise ValueError(f"shading must be 'none' or 'lambert', got {shading!r}")
    light = np.asarray(spec.light_direction) / np.linalg.norm(spec.light_direction)
    # Light the side the camera sees (the ground plane from below, a surface from inside a solid).
    facing = np.where((np.einsum("ij,ij->i", hits.normal, directions) > 0)[:, None], -hits.normal, hits.normal)
    lambert = np.clip(facing @ light, 0.0, None)
    return rgb * (spec.ambient + (1.0 - spec.ambient) * lambert)[:, None]


def render_rays(spec: SceneSpec, origins: np.ndarray, dirs: np.ndarray, shading: Shading = "none") -> np.ndarray:
    """Premultiplied RGBA [N, 4] along rays [N, 3] (colour times hit, and the hit as alpha), in chunks."""
    out = np.empty((len(dirs), 4))
    for start in range(0, len(dirs), _CHUNK_RAYS):
        sl = slice(start, start + _CHUNK_RAYS)
        hits = intersect_scene(spec, origins[sl], dirs[sl])
        out[sl, :3] = shade(spec, hits, dirs[sl], shading)
        out[sl, 3] = hits.hit
    return out


def render_view(
    spec: SceneSpec,
    c2w: np.ndarray,
    width: int,
    height: int,
    camera_angle_x: float,
    shading: Shading = "none",
    samples_per_pixel: int = 1,
) -> np.ndarray:
    """Straight (not premultiplied) RGBA float [H, W, 4]: alpha is the hit fraction, colour the mean hit colour."""
    origins, dirs = pixel_rays(c2w, width, height, camera_angle_x, samples_per_pixel)
    premult = render_rays(spec, origins.reshape(-1, 3), dirs.reshape(-1, 3), shading)
    premult = premult.reshape(height, width, samples_per_pixel**2, 4).mean(axis=2)
    alpha = premult[..., 3:]
    rgb = np.divide(premult[..., :3], alpha, out=np.zeros_like(premult[..., :3]), where=alpha > 0)
    return np.concatenate([rgb, alpha], axis=-1)
