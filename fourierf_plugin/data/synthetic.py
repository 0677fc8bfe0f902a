"""Ground-truth scenes: analytic spheres, boxes and a ground plane rendered by exact ray intersection.

Why: geometry metrics (Chamfer distance of an exported mesh) and renders need a scene whose answer is known
exactly. The renderer simulates only what such a scene needs: coverage (alpha) and the diffuse albedo; Lambert
shading from one directional light is added only when asked. The output is a NeRF-synthetic ("Blender") dataset,
so the ordinary Blender parser reads it, with the analytic geometry saved beside it as ``geometry.json``.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass, fields
from pathlib import Path
from typing import Any, Literal

import imageio.v3 as iio
import numpy as np

from fourierf_plugin.utils.errors import fail

Shading = Literal["none", "lambert"]
Vec3 = tuple[float, float, float]

SCENE_FORMAT = "fourierf-synthetic-scene"
SCENE_VERSION = 1
SPLITS = ("train", "val", "test")
_T_MIN = 1e-9  # hits closer than this along a ray are ignored (a ray starting on a surface does not hit it)
_INSIDE_TOL = 1e-9  # a point is inside a solid only this far below its surface, so rounding never buries samples
_CHUNK_RAYS = 1 << 18  # rays intersected at once: bounds memory at large sizes with supersampling
_GOLDEN_ANGLE = math.pi * (3.0 - math.sqrt(5.0))


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


# -- primitives --------------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class Sphere:
    center: Vec3
    radius: float
    color: Vec3

    def __post_init__(self) -> None:
        object.__setattr__(self, "center", _vec3(self.center, "center"))
        object.__setattr__(self, "radius", _positive(self.radius, "radius"))
        object.__setattr__(self, "color", _color(self.color))

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


@dataclass(frozen=True)
class Box:
    """Axis-aligned box ``center ± half_size``."""

    center: Vec3
    half_size: Vec3
    color: Vec3

    def __post_init__(self) -> None:
        object.__setattr__(self, "center", _vec3(self.center, "center"))
        half = _vec3(self.half_size, "half_size")
        if min(half) <= 0:
            raise ValueError(f"half_size components must be positive, got {self.half_size!r}")
        object.__setattr__(self, "half_size", half)
        object.__setattr__(self, "color", _color(self.color))

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


Primitive = Sphere | Box | GroundPlane
_TYPES: dict[str, type] = {"sphere": Sphere, "box": Box, "ground_plane": GroundPlane}
_TYPE_NAMES = {cls: name for name, cls in _TYPES.items()}


# -- scenes ------------------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class SceneSpec:
    """The primitives of a scene and the light used only by ``shading="lambert"``."""

    primitives: tuple[Primitive, ...]
    light_direction: Vec3 = (0.3, 0.2, 1.0)
    """Direction towards the light (normalised when used)."""
    ambient: float = 0.25
    """Lambert: colour = albedo * (ambient + (1 - ambient) * max(0, n . l))."""

    def __post_init__(self) -> None:
        prims = tuple(self.primitives)
        if not prims:
            raise ValueError("a scene needs at least one primitive")
        for p in prims:
            if not isinstance(p, (Sphere, Box, GroundPlane)):
                raise ValueError(f"unknown primitive {p!r}")
        light = _vec3(self.light_direction, "light_direction")
        if np.linalg.norm(light) == 0:
            raise ValueError("light_direction must be non-zero")
        if not 0.0 <= float(self.ambient) <= 1.0:
            raise ValueError(f"ambient must lie in [0, 1], got {self.ambient!r}")
        object.__setattr__(self, "primitives", prims)
        object.__setattr__(self, "light_direction", light)
        object.__setattr__(self, "ambient", float(self.ambient))

    def bounds(self) -> tuple[np.ndarray, np.ndarray]:
        """Axis-aligned box holding every primitive."""
        boxes = [p.bounds() for p in self.primitives]
        return np.min([b[0] for b in boxes], axis=0), np.max([b[1] for b in boxes], axis=0)

    def to_dict(self) -> dict[str, Any]:
        prims = []
        for p in self.primitives:
            item: dict[str, Any] = {"type": _TYPE_NAMES[type(p)]}
            for f in fields(p):
                value = getattr(p, f.name)
                item[f.name] = list(value) if isinstance(value, tuple) else value
            prims.append(item)
        return {
            "format": SCENE_FORMAT,
            "version": SCENE_VERSION,
            "primitives": prims,
            "light_direction": list(self.light_direction),
            "ambient": self.ambient,
        }

    @classmethod
    def from_dict(cls, data: Any, source: str = "scene") -> SceneSpec:
        """Inverse of :meth:`to_dict`; every defect is a UserError naming ``source`` and the primitive."""
        fix = "repair the file (see geometry.json written by fourierf-synth for the format)"
        if not isinstance(data, dict) or not isinstance(data.get("primitives"), list):
            fail(f"{source} must be a JSON object with a 'primitives' list", fix)
        if data.get("format", SCENE_FORMAT) != SCENE_FORMAT:
            fail(f"{source} has format {data.get('format')!r}, expected {SCENE_FORMAT!r}", fix)
        prims: list[Primitive] = []
        for i, item in enumerate(data["primitives"]):
            kind = item.get("type") if isinstance(item, dict) else None
            if kind not in _TYPES:
                fail(f"{source}, primitive {i}: type must be one of {sorted(_TYPES)}, got {kind!r}", fix)
            kwargs = {k: v for k, v in item.items() if k != "type"}
            try:
                prims.append(_TYPES[kind](**kwargs))
            except (TypeError, ValueError) as err:
                fail(f"{source}, primitive {i} ({kind}): {err}", fix)
        extra = {k: data[k] for k in ("light_direction", "ambient") if k in data}
        try:
            return cls(tuple(prims), **extra)
        except (TypeError, ValueError) as err:
            fail(f"{source}: {err}", fix)


def save_scene(spec: SceneSpec, path: Path, extra: dict[str, Any] | None = None) -> Path:
    """Write ``spec`` as JSON (``extra`` keys, e.g. how it was rendered, are stored beside it and ignored on load)."""
    path = Path(path)
    data = spec.to_dict()
    if extra:
        data.update(extra)
    path.write_text(json.dumps(data, indent=2) + "\n", encoding="utf-8")
    return path


def load_scene(path: Path) -> SceneSpec:
    path = Path(path)
    if not path.is_file():
        fail(f"scene file not found: {path}", "pass the geometry.json of a generated scene")
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
    except json.JSONDecodeError as err:
        fail(f"{path} is not valid JSON: {err.msg} at line {err.lineno}", "repair the file")
    except (UnicodeDecodeError, OSError) as err:
        fail(f"cannot read {path}: {err}", "check the file")
    return SceneSpec.from_dict(data, str(path))


def default_scene(ground_plane: bool = False) -> SceneSpec:
    """Two spheres and a box of distinct colours inside [-1, 1]^3; the box cuts into the large sphere.

    Colours are multiples of 0.2, exact in 8 bits, so unshaded renders hold exactly these values.
    """
    prims: list[Primitive] = [
        Sphere(center=(-0.3, -0.15, 0.0), radius=0.5, color=(0.8, 0.2, 0.2)),
        Sphere(center=(0.5, 0.45, -0.2), radius=0.3, color=(0.2, 0.8, 0.2)),
        Box(center=(0.35, -0.45, -0.25), half_size=(0.3, 0.25, 0.4), color=(0.2, 0.4, 0.8)),
    ]
    if ground_plane:
        prims.append(GroundPlane(height=-0.6, color=(0.6, 0.6, 0.6), half_extent=1.0))
    return SceneSpec(tuple(prims))


# -- intersection and rendering ----------------------------------------------------------------------------------
@dataclass(frozen=True)
class RayHits:
    """Nearest hits of a batch of rays: ``t`` ([N], inf on a miss), ``index`` ([N], -1 on a miss), ``normal``."""

    t: np.ndarray
    index: np.ndarray
    normal: np.ndarray

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
    return RayHits(best_t, index, normal)


def shade(spec: SceneSpec, hits: RayHits, directions: np.ndarray, shading: Shading = "none") -> np.ndarray:
    """Colour [N, 3] of each ray (0 on a miss): the albedo, times the Lambert term when ``shading="lambert"``."""
    albedo = np.array([p.color for p in spec.primitives] + [(0.0, 0.0, 0.0)])
    rgb = albedo[hits.index]  # index -1 picks the trailing black row
    if shading == "none":
        return rgb
    if shading != "lambert":
        raise ValueError(f"shading must be 'none' or 'lambert', got {shading!r}")
    light = np.asarray(spec.light_direction) / np.linalg.norm(spec.light_direction)
    # Light the side the camera sees (the ground plane from below, a surface from inside a solid).
    facing = np.where((np.einsum("ij,ij->i", hits.normal, directions) > 0)[:, None], -hits.normal, hits.normal)
    lambert = np.clip(facing @ light, 0.0, None)
    return rgb * (spec.ambient + (1.0 - spec.ambient) * lambert)[:, None]


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
    o, d = origins.reshape(-1, 3), dirs.reshape(-1, 3)
    premult = np.empty((len(d), 4))
    for start in range(0, len(d), _CHUNK_RAYS):
        sl = slice(start, start + _CHUNK_RAYS)
        hits = intersect_scene(spec, o[sl], d[sl])
        premult[sl, :3] = shade(spec, hits, d[sl], shading)
        premult[sl, 3] = hits.hit
    premult = premult.reshape(height, width, samples_per_pixel**2, 4).mean(axis=2)
    alpha = premult[..., 3:]
    rgb = np.divide(premult[..., :3], alpha, out=np.zeros_like(premult[..., :3]), where=alpha > 0)
    return np.concatenate([rgb, alpha], axis=-1)


def to_uint8(rgba: np.ndarray) -> np.ndarray:
    return np.clip(np.rint(rgba * 255.0), 0, 255).astype(np.uint8)


# -- cameras -----------------------------------------------------------------------------------------------------
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


# -- datasets ----------------------------------------------------------------------------------------------------
def check_scene_fits(
    spec: SceneSpec, cameras: np.ndarray, scene_bound: float = 1.5, near: float = 2.0, far: float = 6.0
) -> None:
    """UserError unless every primitive lies in the parser's box and between its near and far planes.

    Conservative: distances are taken to the scene's bounding box, which holds every surface point.
    """
    lo, hi = spec.bounds()
    b = scene_bound
    if (lo < -b).any() or (hi > b).any():
        fail(
            f"the scene spans {np.round(lo, 3).tolist()} .. {np.round(hi, 3).tolist()}, outside the Blender "
            f"parser's box [-{b}, {b}]^3",
            "move or shrink the primitives so that they fit inside [-1.5, 1.5]^3 (ideally [-1, 1]^3)",
        )
    corners = np.array([[x, y, z] for x in (lo[0], hi[0]) for y in (lo[1], hi[1]) for z in (lo[2], hi[2])])
    for c2w in cameras:
        eye = c2w[:3, 3]
        nearest = np.linalg.norm(np.clip(eye, lo, hi) - eye)
        farthest = np.linalg.norm(corners - eye, axis=1).max()
        if nearest < near or farthest > far:
            fail(
                f"a camera at distance {np.linalg.norm(eye):.3g} sees the scene between {nearest:.3g} and "
                f"{farthest:.3g}, outside the parser's near/far range [{near}, {far}]",
                "keep the camera radius near 4 and the scene inside [-1, 1]^3",
            )


def _check_options(
    width: int, height: int, n_train: int, n_val: int, n_test: int, camera_angle_x: float, radius: float, spp: int
) -> None:
    if width < 8 or height < 8:
        fail(f"image size {width}x{height} is too small", "use --width and --height of at least 8 pixels")
    for name, value in (("--n-train", n_train), ("--n-val", n_val), ("--n-test", n_test)):
        if value < 1:
            fail(f"{name} must be >= 1, got {value}", f"pass {name} 1 or more (every split needs a view)")
    if not 0 < camera_angle_x < math.pi:
        fail(f"--camera-angle-x must lie in (0, pi) radians, got {camera_angle_x}", "the default is 0.69")
    if not radius > 0:
        fail(f"--radius must be > 0, got {radius}", "the default is 4 (the Blender parser's near/far are 2 and 6)")
    if not 1 <= spp <= 16:
        fail(f"--samples-per-pixel must be in 1..16, got {spp}", "use 1 for hard edges or 2-4 for antialiased alpha")


def write_blender_dataset(
    spec: SceneSpec,
    out_dir: Path,
    width: int = 100,
    height: int = 100,
    n_train: int = 4,
    n_val: int = 4,
    n_test: int = 8,
    seed: int = 0,
    camera_angle_x: float = 0.69,
    radius: float = 4.0,
    shading: Shading = "none",
    samples_per_pixel: int = 1,
) -> Path:
    """Render ``spec`` into a NeRF-synthetic scene folder and return it.

    Writes ``transforms_{train,val,test}.json`` (frames ``./<split>/r_<i>``), 8-bit RGBA PNGs with a transparent
    background (the parser composites it on white) and ``geometry.json`` (the scene plus how it was rendered).
    Stale ``r_*.png`` from an earlier generation in the split folders are removed.
    """
    _check_options(width, height, n_train, n_val, n_test, camera_angle_x, radius, samples_per_pixel)
    if shading not in ("none", "lambert"):
        fail(f"shading must be 'none' or 'lambert', got {shading!r}", "pick one of: none, lambert")
    cameras = split_cameras(n_train, n_val, n_test, radius, seed)
    check_scene_fits(spec, np.concatenate(list(cameras.values())))
    out = Path(out_dir)
    if out.exists() and not out.is_dir():
        fail(f"output path {out} is a file", "choose a folder path for the dataset")
    out.mkdir(parents=True, exist_ok=True)
    for split, c2ws in cameras.items():
        folder = out / split
        folder.mkdir(exist_ok=True)
        for stale in folder.glob("r_*.png"):
            stale.unlink()
        frames = []
        for i, c2w in enumerate(c2ws):
            rgba = render_view(spec, c2w, width, height, camera_angle_x, shading, samples_per_pixel)
            iio.imwrite(folder / f"r_{i}.png", to_uint8(rgba))
            frames.append({"file_path": f"./{split}/r_{i}", "rotation": 0.0, "transform_matrix": c2w.tolist()})
        meta = {"camera_angle_x": camera_angle_x, "frames": frames}
        (out / f"transforms_{split}.json").write_text(json.dumps(meta, indent=2) + "\n", encoding="utf-8")
    render = {
        "width": width,
        "height": height,
        "seed": seed,
        "camera_angle_x": camera_angle_x,
        "radius": radius,
        "shading": shading,
        "samples_per_pixel": samples_per_pixel,
        "views": {s: len(c) for s, c in cameras.items()},
    }
    save_scene(spec, out / "geometry.json", extra={"render": render})
    return out


# -- the true surface --------------------------------------------------------------------------------------------
def sample_surface(spec: SceneSpec, n: int, seed: int = 0) -> np.ndarray:
    """[n, 3] points uniform (by area) on the scene's exposed surface: the union of the primitives' surfaces
    without the parts buried inside another solid. This is the reference surface of Chamfer distances.

    Area-weighted sampling with rejection keeps the result uniform over what remains. Surfaces that no camera
    sees (undersides, the faces of a box resting on the ground) are kept: they are exposed, just unobserved.
    """
    if n < 0:
        raise ValueError(f"n must be >= 0, got {n}")
    rng = np.random.default_rng(seed)
    prims = spec.primitives
    areas = np.array([p.area() for p in prims])
    kept: list[np.ndarray] = []
    total = 0
    for _ in range(100):
        if total >= n:
            break
        m = max(2 * (n - total), 64)
        which = rng.choice(len(prims), size=m, p=areas / areas.sum())
        points = np.empty((m, 3))
        visible = np.ones(m, dtype=bool)
        for i, prim in enumerate(prims):
            mine = which == i
            points[mine] = prim.sample(int(mine.sum()), rng)
        for j, other in enumerate(prims):
            visible &= ~((which != j) & other.contains(points))
        kept.append(points[visible])
        total += int(visible.sum())
    if total < n:
        raise ValueError("the scene's surface is (almost) entirely buried inside its solids")
    return np.concatenate(kept)[:n] if kept else np.zeros((0, 3))


def surface_distance(spec: SceneSpec, points: np.ndarray) -> np.ndarray:
    """Unsigned distance [N] of each point to the nearest primitive surface (buried parts included)."""
    points = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    return np.min([p.surface_distance(points) for p in spec.primitives], axis=0)
