"""Procedural surface textures (checkers, tiles, stripes, smooth noise) evaluated on surface coordinates.

Why: a scene of flat colours gives a photo-like capture nothing to match and PSNR nothing to measure; a textured
surface makes every pixel informative while its colour stays an exact function of the surface point.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass
from typing import Any, Literal

import numpy as np

TextureKind = Literal["checker", "tiles", "stripes", "noise"]
TEXTURE_KINDS: tuple[str, ...] = ("checker", "tiles", "stripes", "noise")

_NOISE_OCTAVES = ((1.0, 0.65), (1.0 / 2.7, 0.35))  # (cell size as a share of ``scale``, weight): smooth plus detail


@dataclass(frozen=True)
class Texture:
    """A pattern over a surface's (u, v) coordinates, in scene units (see :func:`surface_uv`).

    checker: cell (i, j) of side ``scale`` takes ``colors[(i + j) % k]``; tiles: a seeded random colour per cell;
    stripes: bands of width ``scale`` across the direction ``angle`` (degrees from u), colours in turn; noise: smooth
    value noise with features of about ``scale``, blended along the colours in order.
    """

    kind: TextureKind
    colors: tuple[tuple[float, float, float], ...]
    scale: float
    angle: float = 0.0
    seed: int = 0

    def __post_init__(self) -> None:
        if self.kind not in TEXTURE_KINDS:
            raise ValueError(f"texture kind must be one of {list(TEXTURE_KINDS)}, got {self.kind!r}")
        try:
            colors = np.asarray(self.colors, dtype=np.float64)
        except (TypeError, ValueError):
            colors = np.empty(0)
        if colors.ndim != 2 or colors.shape[1] != 3 or len(colors) < 2 or not np.isfinite(colors).all():
            raise ValueError(f"texture colors must be a list of 2 or more RGB triples, got {self.colors!r}")
        if ((colors < 0) | (colors > 1)).any():
            raise ValueError(f"texture color components must lie in [0, 1], got {self.colors!r}")
        scale = float(self.scale)
        if not math.isfinite(scale) or scale <= 0:
            raise ValueError(f"texture scale must be a positive number, got {self.scale!r}")
        angle = float(self.angle)
        if not math.isfinite(angle):
            raise ValueError(f"texture angle must be a finite number, got {self.angle!r}")
        if isinstance(self.seed, bool) or int(self.seed) != self.seed:
            raise ValueError(f"texture seed must be a whole number, got {self.seed!r}")
        object.__setattr__(self, "colors", tuple(tuple(float(c) for c in row) for row in colors))
        object.__setattr__(self, "scale", scale)
        object.__setattr__(self, "angle", angle)
        object.__setattr__(self, "seed", int(self.seed))

    def to_dict(self) -> dict[str, Any]:
        data = asdict(self)
        data["colors"] = [list(c) for c in self.colors]
        return data

    def color_at(self, uv: np.ndarray) -> np.ndarray:
        """RGB [N, 3] at surface coordinates ``uv`` [N, 2]."""
        uv = np.asarray(uv, dtype=np.float64).reshape(-1, 2)
        colors = np.asarray(self.colors)
        k = len(colors)
        if self.kind == "noise":
            level = _value_noise(uv / self.scale, self.seed) * (k - 1)  # in [0, k - 1]
            low = np.clip(np.floor(level).astype(np.int64), 0, k - 2)
            frac = (level - low)[:, None]
            return colors[low] * (1.0 - frac) + colors[low + 1] * frac
        if self.kind == "stripes":
            a = math.radians(self.angle)
            band = np.floor((uv[:, 0] * math.cos(a) + uv[:, 1] * math.sin(a)) / self.scale).astype(np.int64)
            return colors[np.mod(band, k)]
        cell = np.floor(uv / self.scale).astype(np.int64)
        if self.kind == "checker":
            return colors[np.mod(cell[:, 0] + cell[:, 1], k)]
        return colors[(_hash(cell[:, 0], cell[:, 1], self.seed) % np.uint64(k)).astype(np.int64)]  # tiles


def texture_from(value: Any) -> Texture | None:
    """None, a :class:`Texture`, or its dict form (as geometry.json stores it) as a Texture."""
    if value is None or isinstance(value, Texture):
        return value
    if not isinstance(value, dict):
        raise ValueError(f"texture must be an object with kind, colors and scale, got {value!r:.80}")
    try:
        return Texture(**value)
    except TypeError as err:
        raise ValueError(f"texture: {err}") from None


def surface_uv(points: np.ndarray, normals: np.ndarray, sphere_center: np.ndarray | None = None) -> np.ndarray:
    """(u, v) [N, 2] of surface points in scene units: on a flat axis-aligned face, the two world coordinates along
    the face (the normal's largest component names the dropped axis); on a sphere about ``sphere_center``, arc
    lengths along longitude and latitude."""
    points = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    if sphere_center is not None:
        q = points - np.asarray(sphere_center, dtype=np.float64)
        r = np.linalg.norm(q, axis=1)
        safe = np.where(r > 0, r, 1.0)
        return np.stack([r * np.arctan2(q[:, 1], q[:, 0]), r * np.arcsin(np.clip(q[:, 2] / safe, -1, 1))], axis=1)
    axis = np.abs(np.asarray(normals, dtype=np.float64).reshape(-1, 3)).argmax(axis=1)
    keep = np.array([[1, 2], [0, 2], [0, 1]])[axis]  # the two in-face axes, in increasing order
    return np.take_along_axis(points, keep, axis=1)


def _hash(i: np.ndarray, j: np.ndarray, seed: int) -> np.ndarray:
    """A well-mixed uint64 per integer lattice point (wrapping arithmetic, as in integer hash functions)."""
    with np.errstate(over="ignore"):
        h = i.astype(np.int64).view(np.uint64) * np.uint64(0x9E3779B97F4A7C15)
        h ^= j.astype(np.int64).view(np.uint64) * np.uint64(0xC2B2AE3D27D4EB4F)
        h ^= np.uint64((seed * 0x165667B19E3779F9) % (1 << 64))
        h ^= h >> np.uint64(31)
        h *= np.uint64(0xBF58476D1CE4E5B9)
        h ^= h >> np.uint64(29)
    return h


def _value_noise(uv: np.ndarray, seed: int) -> np.ndarray:
    """Smooth noise in [0, 1] ([N]): seeded random values at lattice points, blended with smoothstep weights."""
    total = np.zeros(len(uv))
    for octave, (size, weight) in enumerate(_NOISE_OCTAVES):
        p = uv / size
        cell = np.floor(p).astype(np.int64)
        f = p - cell
        w = f * f * (3.0 - 2.0 * f)

        def corner(di: int, dj: int, octave: int = octave, cell: np.ndarray = cell) -> np.ndarray:
            h = _hash(cell[:, 0] + di, cell[:, 1] + dj, seed * 7 + octave)
            return (h >> np.uint64(11)).astype(np.float64) / float(1 << 53)

        bottom = corner(0, 0) * (1 - w[:, 0]) + corner(1, 0) * w[:, 0]
        top = corner(0, 1) * (1 - w[:, 0]) + corner(1, 1) * w[:, 0]
        total += weight * (bottom * (1 - w[:, 1]) + top * w[:, 1])
    return np.clip(total, 0.0, 1.0)
