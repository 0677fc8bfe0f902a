"""Analytic primitives (sphere, axis-aligned box, ground square, wall panel): exact ray hits, inside tests, area
sampling, and the colour of a surface point (a flat colour, or a procedural texture)."""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from fourierf_plugin.synthetic.textures import Texture, surface_uv, texture_from

Vec3 = tuple[float, float, float]

_T_MIN = 1e-9  # hits closer than this along a ray are ignored (a ray starting on a surface does not hit it)
_INSIDE_TOL = 1e-9  # a point is inside a solid only this far below its surface, so rounding never buries samples


def _vec3(value: Any, name: str) -> Vec3:
    arr = np.asarray(value, dtype=np.float64)
    if arr.shape != (3,) or not np.isfinite(arr).all():
        raise ValueError(f"{name} must be 3 finite numbers, got {value!r}")
    return (float(arr[0]), float(arr[1]), float(arr[2]))


def _color(value: Any) -> Vec3:
    rgb = _vec3(value, "color")
    if not all(0.0 <= c <= 1.0 for c in rgb):
        raise ValueError(f"color components must lie in [0, 1], got {value!r}")
    return rgb


def _positive(value: Any, name: str) -> float:
    number = float(value)
    if not math.isfinite(number) or number <= 0:
        raise ValueError(f"{name} must be a positive number, got {value!r}")
    return number


@dataclass(frozen=True)
class Sphere:
    """A sphere; with a ``texture`` its surface takes the texture's colours (``color`` is then only nominal)."""

    center: Vec3
    radius: float
    color: Vec3
    texture: Texture | None = None

    def __post_init__(self) -> None:
        object.__setattr__(self, "center", _vec3(self.center, "center"))
        object.__setattr__(self, "radius", _positive(self.radius, "radius"))
        object.__setattr__(self, "color", _color(self.color))
        object.__setattr__(self, "texture", texture_from(self.texture))

    def intersect(self, origins: np.ndarray, directions: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Nearest hit parameter t > 0 ([N], inf on a miss; o + t d) and the outward unit normal there ([N, 3])."""
        c = np.asarray(self.center)
        oc = origins - c
        a = np.einsum("ij,ij->i", directions, directions)
        b = np.einsum("ij,ij->i", oc, directions)
        disc = b * b - a * (np.einsum("ij,ij->i", oc, oc) - self.radius**2)
        root = np.sqrt(np.maximum(disc, 0.0))
        with np.errstate(divide="ignore", invalid="ignore"):
            t_near, t_far = (-b - root) / a, (-b + root) / a
        t = np.where(t_near > _T_MIN, t_near, t_far)  # the far root when the ray starts inside
        t = np.where((disc >= 0) & (t > _T_MIN), t, np.inf)
        hit = np.isfinite(t)
        normals = np.zeros_like(origins)
        normals[hit] = (origins[hit] + t[hit, None] * directions[hit] - c) / self.radius
        return t, normals

    def area(self) -> float:
        return 4.0 * math.pi * self.radius**2

    def sample(self, n: int, rng: np.random.Generator) -> np.ndarray:
        v = rng.standard_normal((n, 3))
        v /= np.linalg.norm(v, axis=1, keepdims=True)
        return np.asarray(self.center) + self.radius * v

    def contains(self, points: np.ndarray) -> np.ndarray:
        """Inside the solid by more than rounding (points on the surface are not inside)."""
        return np.linalg.norm(points - np.asarray(self.center), axis=1) < self.radius - _INSIDE_TOL

    def surface_distance(self, points: np.ndarray) -> np.ndarray:
        return np.abs(np.linalg.norm(points - np.asarray(self.center), axis=1) - self.radius)

    def bounds(self) -> tuple[np.ndarray, np.ndarray]:
        c = np.asarray(self.center)
        return c - self.radius, c + self.radius

    def color_at(self, points: np.ndarray, normals: np.ndarray) -> np.ndarray:
        """RGB [N, 3] of surface points (the texture over longitude and latitude arc lengths)."""
        return _surface_color(self, points, normals, np.asarray(self.center))


@dataclass(frozen=True)
class Box:
    """Axis-aligned box ``center ± half_size``; with a ``texture`` each face takes it over its two world axes."""

    center: Vec3
    half_size: Vec3
    color: Vec3
    texture: Texture | None = None

    def __post_init__(self) -> None:
        object.__setattr__(self, "center", _vec3(self.center, "center"))
        half = _vec3(self.half_size, "half_size")
        if min(half) <= 0:
            raise ValueError(f"half_size components must be positive, got {self.half_size!r}")
        object.__setattr__(self, "half_size", half)
        object.__setattr__(self, "color", _color(self.color))
        object.__setattr__(self, "texture", texture_from(self.texture))

    def intersect(self, origins: np.ndarray, directions: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Slab test; nearest t > 0 ([N], inf on a miss) and the outward unit face normal ([N, 3])."""
        lo, hi = self.bounds()
        parallel = directions == 0
        safe = np.where(parallel, 1.0, directions)
        t1, t2 = (lo - origins) / safe, (hi - origins) / safe
        t_lo, t_hi = np.minimum(t1, t2), np.maximum(t1, t2)
        # A ray parallel to a slab never crosses it: inside the slab it is unbounded, outside it misses.
        inside_slab = (origins >= lo) & (origins <= hi)
        t_lo = np.where(parallel, np.where(inside_slab, -np.inf, np.inf), t_lo)
        t_hi = np.where(parallel, np.where(inside_slab, np.inf, -np.inf), t_hi)
        t_enter, t_exit = t_lo.max(axis=1), t_hi.min(axis=1)
        t = np.where(t_enter > _T_MIN, t_enter, t_exit)  # the exit when the ray starts inside
        t = np.where((t_exit >= t_enter) & (t > _T_MIN), t, np.inf)
        hit = np.isfinite(t)
        normals = np.zeros_like(origins)
        if hit.any():
            q = (origins[hit] + t[hit, None] * directions[hit] - np.asarray(self.center)) / np.asarray(self.half_size)
            axis = np.abs(q).argmax(axis=1)
            rows = np.flatnonzero(hit)
            normals[rows, axis] = np.sign(q[np.arange(len(rows)), axis])
        return t, normals

    def _face_areas(self) -> np.ndarray:
        hx, hy, hz = self.half_size
        return np.array([4 * hy * hz, 4 * hx * hz, 4 * hx * hy])  # one face normal to x, y, z

    def area(self) -> float:
        return float(2.0 * self._face_areas().sum())

    def sample(self, n: int, rng: np.random.Generator) -> np.ndarray:
        half = np.asarray(self.half_size)
        areas = self._face_areas()
        axis = rng.choice(3, size=n, p=areas / areas.sum())
        q = rng.uniform(-1.0, 1.0, size=(n, 3))
        q[np.arange(n), axis] = rng.choice([-1.0, 1.0], size=n)
        return np.asarray(self.center) + q * half

    def contains(self, points: np.ndarray) -> np.ndarray:
        return (np.abs(points - np.asarray(self.center)) < np.asarray(self.half_size) - _INSIDE_TOL).all(axis=1)

    def surface_distance(self, points: np.ndarray) -> np.ndarray:
        d = np.abs(points - np.asarray(self.center)) - np.asarray(self.half_size)
        outside = np.linalg.norm(np.maximum(d, 0.0), axis=1)
        inside = -np.minimum(d.max(axis=1), 0.0)
        return outside + inside

    def bounds(self) -> tuple[np.ndarray, np.ndarray]:
        c, h = np.asarray(self.center), np.asarray(self.half_size)
        return c - h, c + h

    def color_at(self, points: np.ndarray, normals: np.ndarray) -> np.ndarray:
        """RGB [N, 3] of surface points (``normals``, axis-aligned, name each point's face)."""
        return _surface_color(self, points, normals)


@dataclass(frozen=True)
class GroundPlane:
    """The square ``|x|, |y| <= half_extent`` at ``z = height``: a surface without volume, normal +z."""

    height: float = -0.6
    color: Vec3 = (0.6, 0.6, 0.6)
    half_extent: float = 1.2

    def __post_init__(self) -> None:
        height = float(self.height)
        if not math.isfinite(height):
            raise ValueError(f"height must be a finite number, got {self.height!r}")
        object.__setattr__(self, "height", height)
        object.__setattr__(self, "color", _color(self.color))
        object.__setattr__(self, "half_extent", _positive(self.half_extent, "half_extent"))

    def intersect(self, origins: np.ndarray, directions: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        dz = directions[:, 2]
        with np.errstate(divide="ignore", invalid="ignore"):
            t = (self.height - origins[:, 2]) / dz
        p = origins + np.where(np.isfinite(t), t, 0.0)[:, None] * directions
        on_square = (np.abs(p[:, :2]) <= self.half_extent).all(axis=1)
        t = np.where((dz != 0) & (t > _T_MIN) & on_square, t, np.inf)
        normals = np.zeros_like(origins)
        normals[np.isfinite(t), 2] = 1.0
        return t, normals

    def area(self) -> float:
        return (2.0 * self.half_extent) ** 2

    def sample(self, n: int, rng: np.random.Generator) -> np.ndarray:
        xy = rng.uniform(-self.half_extent, self.half_extent, size=(n, 2))
        return np.concatenate([xy, np.full((n, 1), self.height)], axis=1)

    def contains(self, points: np.ndarray) -> np.ndarray:
        return np.zeros(len(points), dtype=bool)  # no volume

    def surface_distance(self, points: np.ndarray) -> np.ndarray:
        outside = np.maximum(np.abs(points[:, :2]) - self.half_extent, 0.0)
        return np.sqrt((outside**2).sum(axis=1) + (points[:, 2] - self.height) ** 2)

    def bounds(self) -> tuple[np.ndarray, np.ndarray]:
        e = self.half_extent
        return np.array([-e, -e, self.height]), np.array([e, e, self.height])


@dataclass(frozen=True)
class Panel:
    """The axis-aligned rectangle ``center ± half_size`` with exactly one zero half size (its normal axis): a wall,
    floor or ceiling, without volume and seen from both sides. Six of them close a room (:func:`room_panels`)."""

    center: Vec3
    half_size: Vec3
    color: Vec3
    texture: Texture | None = None

    def __post_init__(self) -> None:
        object.__setattr__(self, "center", _vec3(self.center, "center"))
        half = _vec3(self.half_size, "half_size")
        if sum(h == 0 for h in half) != 1 or min(half) < 0:
            raise ValueError(f"half_size must have exactly one zero (the normal axis), others > 0, got {half!r}")
        object.__setattr__(self, "half_size", half)
        object.__setattr__(self, "color", _color(self.color))
        object.__setattr__(self, "texture", texture_from(self.texture))

    @property
    def axis(self) -> int:
        return self.half_size.index(0.0)

    def _in_plane(self) -> list[int]:
        return [i for i in range(3) if i != self.axis]

    def intersect(self, origins: np.ndarray, directions: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Hit t > 0 ([N], inf on a miss) and the unit normal facing the ray's origin ([N, 3]).

        The rectangle is closed and grown by ``_EDGE_TOL``, so rays along the shared edge of two panels never slip
        between them.
        """
        a, c, h = self.axis, np.asarray(self.center), np.asarray(self.half_size)
        d = directions[:, a]
        with np.errstate(divide="ignore", invalid="ignore"):
            t = (c[a] - origins[:, a]) / d
        p = origins + np.where(np.isfinite(t), t, 0.0)[:, None] * directions
        rest = self._in_plane()
        on_rect = (np.abs(p[:, rest] - c[rest]) <= h[rest] + _EDGE_TOL).all(axis=1)
        t = np.where((d != 0) & (t > _T_MIN) & on_rect, t, np.inf)
        normals = np.zeros_like(origins)
        hit = np.isfinite(t)
        normals[hit, a] = -np.sign(d[hit])
        return t, normals

    def area(self) -> float:
        h = np.asarray(self.half_size)[self._in_plane()]
        return float(4.0 * h[0] * h[1])

    def sample(self, n: int, rng: np.random.Generator) -> np.ndarray:
        q = rng.uniform(-1.0, 1.0, size=(n, 3))
        q[:, self.axis] = 0.0
        return np.asarray(self.center) + q * np.asarray(self.half_size)

    def contains(self, points: np.ndarray) -> np.ndarray:
        return np.zeros(len(points), dtype=bool)  # no volume

    def surface_distance(self, points: np.ndarray) -> np.ndarray:
        d = np.abs(points - np.asarray(self.center)) - np.asarray(self.half_size)
        return np.linalg.norm(np.where(np.arange(3) == self.axis, np.abs(d), np.maximum(d, 0.0)), axis=1)

    def bounds(self) -> tuple[np.ndarray, np.ndarray]:
        c, h = np.asarray(self.center), np.asarray(self.half_size)
        return c - h, c + h

    def color_at(self, points: np.ndarray, normals: np.ndarray) -> np.ndarray:
        """RGB [N, 3] of surface points (the texture over the panel's two world axes)."""
        normal = np.zeros((len(points), 3))
        normal[:, self.axis] = 1.0
        return _surface_color(self, points, normal)


_EDGE_TOL = 1e-9  # panels are grown by this much in their plane: adjoining panels overlap instead of leaving cracks


def room_panels(
    low: Vec3, high: Vec3, floor: Texture, ceiling: Texture, walls: tuple[Texture, Texture, Texture, Texture]
) -> tuple[Panel, ...]:
    """The six panels of the room ``low .. high`` (z up): floor, ceiling, then the walls at x = low, x = high,
    y = low, y = high. Each panel's nominal colour is its texture's first colour."""
    lo, hi = np.asarray(_vec3(low, "low")), np.asarray(_vec3(high, "high"))
    if (hi <= lo).any():
        raise ValueError(f"a room needs low < high on every axis, got {low!r} .. {high!r}")
    centre, half = (lo + hi) / 2, (hi - lo) / 2
    panels = []
    for axis, value, texture in (
        (2, lo[2], floor),
        (2, hi[2], ceiling),
        (0, lo[0], walls[0]),
        (0, hi[0], walls[1]),
        (1, lo[1], walls[2]),
        (1, hi[1], walls[3]),
    ):
        c, h = centre.copy(), half.copy()
        c[axis], h[axis] = value, 0.0
        panels.append(Panel(tuple(c), tuple(h), texture.colors[0], texture))
    return tuple(panels)


def _surface_color(
    prim: Sphere | Box | Panel, points: np.ndarray, normals: np.ndarray, sphere_center: np.ndarray | None = None
) -> np.ndarray:
    if prim.texture is None:
        return np.broadcast_to(np.asarray(prim.color), (len(points), 3)).copy()
    return prim.texture.color_at(surface_uv(points, normals, sphere_center))


Primitive = Sphere | Box | GroundPlane | Panel
