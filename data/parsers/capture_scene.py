"""From a capture's poses to a normalised scene, and the call between a forward-facing capture and an object.

Forward-facing captures (every camera on one side, looking the same way) are normalised exactly as the LLFF parser
does it, so a scene trains the same through ``poses_bounds.npy`` and through a ``transforms.json``: scaled so the
nearest depth bound is 1 / bd_factor, recentred on the average pose, rays later mapped to NDC. Object (360°)
captures are normalised as nerfstudio does: turned upright, centred where the cameras look, scaled so the cameras fit
the unit box; the scene box comes from the sparse points when there are some.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

import numpy as np

from fourierf_plugin.data.capture import Capture, Intrinsics
from fourierf_plugin.data.parsers.llff import NDC_BOX
from fourierf_plugin.data.poses import Orientation, focus_point, orientation_rotation, recenter_poses
from fourierf_plugin.utils.errors import fail

SceneKind = Literal["object", "forward-facing", "unbounded"]

VIEW_CONE_DEG = 50.0
"""A forward-facing capture: every camera looks within this angle of the cameras' mean viewing direction."""
SURROUND_DEG = 30.0
"""Cameras surround the scene when, seen from its centre, one lies more than this from the cameras' mean direction
(a capture spanning more than ~60° around it); LLFF rigs span a few degrees."""
DEPTH_PERCENTILES = (0.1, 99.9)
"""Near and far of a camera from the depths of the sparse points it sees (LLFF's imgs2poses)."""
BOX_PERCENTILES = (1.0, 99.0)
"""The object box holds the sparse points between these per-axis percentiles (stray points left out) ..."""
BOX_PADDING = 0.05
"""... padded by this share of its size on each side."""
MIN_BOX_POINTS = 10
"""Fewer sparse points than this say nothing about where the object is: the box then comes from the cameras."""
SEEN_BY_SHARE = 0.9
"""An unbounded capture's object is held by this share of the photos (in their central part, :data:`CENTRAL_FRAME`;
in frame at all when the cameras' axes do not converge): a photographer keeps the object in frame while its
surroundings drift in and out."""
CENTRAL_FRAME = 0.6
"""A photo's central part: within this share of the half-width and half-height of the principal point, and within
this share of the half-frame's reach (at the focus's depth) of the focus in depth. The photographer aims at the
object, so it stays there from every viewpoint, while a table around it slides to the frame's edges as the camera
moves and a wall behind it lies far beyond the focus; more than half, so an object framed large keeps its edges."""
OBJECT_BOX_PADDING = 0.15
"""The object's box is padded more than a scene box: sparse points thin out at an object's silhouette, and a mesh
cut at the box must not lose the object's top."""
OBJECT_NEAR = 0.05
"""Near plane of an object scene, in its units (the cameras fit the unit box): rays never sample at the lens."""
UNBOUNDED_FAR = 1000.0
"""Far plane of an unbounded scene, in its units: the contraction maps it next to the grid's outer face."""
CONTRACTED_BOX = ((-2.0, -2.0, -2.0), (2.0, 2.0, 2.0))
"""The grid of an unbounded scene covers the contracted space."""


@dataclass(frozen=True)
class KindDecision:
    kind: SceneKind
    reason: str


@dataclass(frozen=True)
class NormalisedScene:
    """The poses the model sees and the region it models."""

    camera_to_worlds: np.ndarray  # [N, 3, 4] float64, OpenGL, in capture frame order
    scene_box: np.ndarray  # [2, 3] (min, max)
    near: float
    far: float
    depth_bounds: tuple[float, float] | None  # metric (near, far) of the content of a forward-facing scene
    object_box: np.ndarray | None = None  # [2, 3] an unbounded scene's object: what (nearly) every camera sees


def camera_to_worlds(capture: Capture) -> np.ndarray:
    """[N, 3, 4] float64 camera-to-worlds of the capture's frames, in order."""
    return np.stack([np.asarray(f.camera_to_world, dtype=np.float64)[:3, :4] for f in capture.frames])


def _intrinsics(capture: Capture) -> list[Intrinsics]:
    return [f.intrinsics for f in capture.frames]


def _finite_points(capture: Capture) -> np.ndarray:
    points = np.asarray(capture.points, dtype=np.float64).reshape(-1, 3)
    return points[np.isfinite(points).all(axis=1)]


def _unit(v: np.ndarray) -> np.ndarray:
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


def _angles_deg(directions: np.ndarray, axis: np.ndarray) -> np.ndarray:
    return np.degrees(np.arccos(np.clip(_unit(directions) @ _unit(axis), -1.0, 1.0)))


def scene_centre(capture: Capture) -> np.ndarray | None:
    """Where the content is: the sparse points' median; else the depth bounds' middle in front of the cameras; else
    the cameras' focus; None when none of these is known (parallel optical axes and no points nor bounds)."""
    points = _finite_points(capture)
    if len(points):
        return np.median(points, axis=0)
    c2w = camera_to_worlds(capture)
    bounds = [f.depth_bounds for f in capture.frames]
    if all(b is not None for b in bounds):
        depth = float(np.median([np.sqrt(near * far) for near, far in bounds]))  # type: ignore[misc]
        view = _unit(-c2w[:, :, 2].sum(axis=0))
        return c2w[:, :, 3].mean(axis=0) + depth * view
    return focus_point(c2w)


def decide_scene_kind(capture: Capture) -> KindDecision:
    """Forward-facing when every camera looks within ``VIEW_CONE_DEG`` of the mean viewing direction and the cameras
    do not surround the scene (``SURROUND_DEG``); an object (360°) capture otherwise."""
    c2w = camera_to_worlds(capture)
    views = _unit(-c2w[:, :, 2])
    mean_view = views.sum(axis=0)
    if np.linalg.norm(mean_view) < 1e-6 * len(views):
        return KindDecision("object", "the cameras look in every direction: a capture around the scene")
    angles = _angles_deg(views, mean_view)
    worst = int(angles.argmax())
    if angles[worst] > VIEW_CONE_DEG:
        name = capture.frames[worst].image_path.name
        return KindDecision(
            "object",
            f"camera {name} looks {angles[worst]:.0f}° away from the cameras' mean viewing direction (a forward-facing "
            f"capture stays within {VIEW_CONE_DEG:.0f}°): a capture around the scene",
        )
    looks = f"every camera looks within {angles.max():.0f}° of the mean viewing direction"
    centre = scene_centre(capture)
    if centre is None:
        return KindDecision("forward-facing", f"{looks} and their optical axes run nearly parallel")
    sides = c2w[:, :, 3] - centre
    sides = sides[np.linalg.norm(sides, axis=1) > 1e-12]
    spread = float(_angles_deg(sides, _unit(sides).sum(axis=0)).max()) if len(sides) else 0.0
    if spread > SURROUND_DEG:
        return KindDecision(
            "object",
            f"{looks}, but seen from the scene's centre the cameras lie up to {spread:.0f}° apart from their mean "
            f"direction (more than {SURROUND_DEG:.0f}°): they surround it",
        )
    return KindDecision(
        "forward-facing", f"{looks}, and seen from the scene's centre all cameras lie within {spread:.0f}° of one side"
    )


def _in_view(points: np.ndarray, pose: np.ndarray, k: Intrinsics) -> tuple[np.ndarray, np.ndarray]:
    """Each point's depth in front of a camera (OpenGL, looking down -z) and whether it projects inside its image
    (distortion left out: callers take percentiles or counts)."""
    local = (points - pose[:, 3]) @ pose[:, :3]
    depth = -local[:, 2]
    front = depth > 1e-9
    safe = np.where(front, depth, 1.0)
    u = k.fx * local[:, 0] / safe + k.cx
    v = -k.fy * local[:, 1] / safe + k.cy
    return depth, front & (u >= 0) & (u <= k.width) & (v >= 0) & (v <= k.height)


def _depths_seen(capture: Capture, points: np.ndarray) -> list[np.ndarray]:
    """Per frame, the depths of the points in front of the camera that project inside its image."""
    seen = []
    for frame in capture.frames:
        depth, inside = _in_view(points, np.asarray(frame.camera_to_world, dtype=np.float64)[:3, :4], frame.intrinsics)
        seen.append(depth[inside])
    return seen


def frame_depth_bounds(capture: Capture) -> np.ndarray:
    """[N, 2] metric (near, far) per frame: as the file gives them, else from the sparse points each camera sees
    (a camera that sees none takes the nearest and farthest of the others)."""
    given = [f.depth_bounds for f in capture.frames]
    if all(b is not None for b in given):
        return np.asarray(given, dtype=np.float64)
    points = _finite_points(capture)
    if not len(points):
        fail(
            f"{capture.source}: a forward-facing scene needs the depth range the cameras see, and this capture has "
            "neither depth_bounds on every frame nor sparse points",
            "add a ply_file_path with the sparse points (fourierf-process-data writes it) or per-frame depth_bounds "
            "[near, far], or pass --scene-kind object",
        )
    seen = _depths_seen(capture, points)
    from_points = [np.percentile(d, DEPTH_PERCENTILES) if len(d) else None for d in seen]
    known = [b for b in from_points if b is not None]
    if not known:
        fail(
            f"{capture.source}: no sparse point lies in front of any camera, so the scene's depth range is unknown",
            "check that the points and the poses share one world frame, or pass --scene-kind object",
        )
    fallback = (min(b[0] for b in known), max(b[1] for b in known))
    rows = [g if g is not None else (p if p is not None else fallback) for g, p in zip(given, from_points, strict=True)]
    bounds = np.asarray(rows, dtype=np.float64)
    if not ((bounds > 0).all() and (bounds[:, 0] < bounds[:, 1]).all()):
        fail(
            f"{capture.source}: the points give a camera an empty depth range (near >= far)",
            "add per-frame depth_bounds [near, far], or pass --scene-kind object",
        )
    return bounds


def normalise_forward_facing(capture: Capture, bd_factor: float) -> NormalisedScene:
    """LLFF's normalisation: the nearest depth bound becomes 1 / bd_factor, the average pose the identity; the box
    and near/far are NDC's."""
    c2w = camera_to_worlds(capture)
    bounds = frame_depth_bounds(capture)
    scale = 1.0 / (bounds.min() * bd_factor)
    c2w[:, :, 3] *= scale
    bounds = bounds * scale
    return NormalisedScene(
        recenter_poses(c2w), np.asarray(NDC_BOX, dtype=np.float64), 0.0, 1.0, (float(bounds.min()), float(bounds.max()))
    )


def _box_from_points(points: np.ndarray) -> np.ndarray:
    low, high = np.percentile(points, BOX_PERCENTILES, axis=0)
    size = high - low
    size = np.maximum(size, 0.1 * size.max())  # a flat cloud (a wall, a poster) still gets some depth
    middle = (low + high) / 2
    half = size * (0.5 + BOX_PADDING)
    return np.stack([middle - half, middle + half])


def _box_from_views(c2w: np.ndarray, capture: Capture) -> np.ndarray:
    """A cube about the focus (the origin) that the cameras see whole: half-size distance x tan(half the narrower
    field of view), the largest over cameras. Blender's lego rig (distance 4, 40° field) gives its 1.5 box."""
    tan_half_fov = np.array([min(k.width / (2 * k.fx), k.height / (2 * k.fy)) for k in _intrinsics(capture)])
    half = float((np.linalg.norm(c2w[:, :, 3], axis=1) * tan_half_fov).max())
    return np.array([[-half] * 3, [half] * 3])


def _upright_centred(capture: Capture, orientation: Orientation) -> tuple[np.ndarray, np.ndarray, bool]:
    """Poses turned upright, centred on the cameras' focus (their mean centre when the axes do not converge) and
    scaled so the cameras fit [-1, 1]³; the sparse points in the same frame; whether the axes converge."""
    c2w = camera_to_worlds(capture)
    rotation = orientation_rotation(c2w, orientation)
    c2w = np.concatenate([rotation @ c2w[:, :, :3], (c2w[:, :, 3] @ rotation.T)[:, :, None]], axis=2)
    points = _finite_points(capture) @ rotation.T
    focus = focus_point(c2w)
    centre = focus if focus is not None else c2w[:, :, 3].mean(axis=0)
    c2w[:, :, 3] -= centre
    extent = float(np.abs(c2w[:, :, 3]).max())
    scale = 1.0 / extent if extent > 1e-12 else 1.0
    c2w[:, :, 3] *= scale
    return c2w, (points - centre) * scale, focus is not None


def normalise_object(capture: Capture, orientation: Orientation, scene_scale: float) -> NormalisedScene:
    """nerfstudio-like: turned upright (``orientation``), centred on the cameras' focus (their mean centre when the
    axes do not converge), scaled so the cameras fit [-1, 1]^3. The box holds the sparse points (robust percentiles,
    padded); without points, what the converging cameras see whole, else the cameras' cube; ``scene_scale`` then
    grows or shrinks it about its centre."""
    c2w, points, converge = _upright_centred(capture, orientation)
    if len(points) >= MIN_BOX_POINTS:
        box = _box_from_points(points)
    elif converge:
        box = _box_from_views(c2w, capture)
    else:
        box = np.array([[-1.0] * 3, [1.0] * 3])
    middle = box.mean(axis=0)
    box = middle + (box - middle) * scene_scale
    corners = np.stack(np.meshgrid(*box.T, indexing="ij"), axis=-1).reshape(-1, 3)
    far = float(np.linalg.norm(corners[None] - c2w[:, None, :, 3], axis=-1).max())
    return NormalisedScene(c2w, box, OBJECT_NEAR, max(far, 2 * OBJECT_NEAR), None)


def normalise_unbounded(capture: Capture, orientation: Orientation) -> NormalisedScene:
    """An object with its surroundings: posed as an object capture (the cameras fit the inner cube [-1, 1]³ about
    their focus), everything beyond the inner cube contracted (mip-NeRF 360); the grid covers the contracted box."""
    c2w, points, converge = _upright_centred(capture, orientation)
    box = np.asarray(CONTRACTED_BOX, dtype=np.float64)
    return NormalisedScene(c2w, box, OBJECT_NEAR, UNBOUNDED_FAR, None, _object_box(c2w, capture, points, converge))


def _box_from_object_points(points: np.ndarray) -> np.ndarray:
    """Robust percentiles of the object's points, padded by ``OBJECT_BOX_PADDING``, cut to the inner cube."""
    low, high = np.percentile(points, BOX_PERCENTILES, axis=0)
    pad = OBJECT_BOX_PADDING * (high - low)
    return np.stack([np.maximum(low - pad, -1.0), np.minimum(high + pad, 1.0)])


def _object_box(c2w: np.ndarray, capture: Capture, points: np.ndarray, converge: bool) -> np.ndarray | None:
    """The object's box of an unbounded scene (the focus at the origin when ``converge``): what the photos aim at
    (:func:`_box_aimed_at`), else the points nearly every camera sees (:func:`_box_seen_by_most`); None when neither
    has ``MIN_BOX_POINTS`` points."""
    aimed = _box_aimed_at(c2w, capture, points) if converge else None
    return aimed if aimed is not None else _box_seen_by_most(c2w, capture, points)


def _box_aimed_at(c2w: np.ndarray, capture: Capture, points: np.ndarray) -> np.ndarray | None:
    """The box of the sparse points in the central part (:data:`CENTRAL_FRAME`) of at least ``SEEN_BY_SHARE`` of the
    photos, about the cameras' focus at the origin; None with too few. The points show only the object's side facing
    the cameras, and the photographer aims at the object's middle: those in front of the focus are mirrored behind it
    along the level mean viewing direction, so the box also holds the side no photo sees."""
    focus = np.zeros(3)
    central = np.zeros(len(points), dtype=np.int64)
    for pose, k in zip(c2w, _intrinsics(capture), strict=True):
        local = (points - pose[:, 3]) @ pose[:, :3]
        depth = -local[:, 2]
        safe = np.where(depth > 1e-9, depth, 1.0)
        horizontal = np.abs(k.fx * local[:, 0] / safe) / (k.width / 2)
        vertical = np.abs(k.fy * local[:, 1] / safe) / (k.height / 2)
        focus_depth = float((pose[:, 3] - focus) @ pose[:, 2])
        reach = focus_depth * max(k.width / (2 * k.fx), k.height / (2 * k.fy))
        near_focus = np.abs(depth - focus_depth) <= CENTRAL_FRAME * reach
        central += (depth > 1e-9) & (horizontal <= CENTRAL_FRAME) & (vertical <= CENTRAL_FRAME) & near_focus
    kept = points[central >= SEEN_BY_SHARE * len(c2w)]
    if len(kept) < MIN_BOX_POINTS:
        return None
    up = _unit(c2w[:, :, 1].sum(axis=0))
    view = -c2w[:, :, 2].sum(axis=0)
    view = view - (view @ up) * up  # level: the photographer walks around the object, not over it
    if np.linalg.norm(view) > 1e-6 * len(c2w):
        view = _unit(view)
        towards_cameras = np.minimum((kept - focus) @ view, 0.0)
        kept = np.concatenate([kept, kept - 2 * towards_cameras[:, None] * view])
    return _box_from_object_points(kept)


def _box_seen_by_most(c2w: np.ndarray, capture: Capture, points: np.ndarray) -> np.ndarray | None:
    """The sparse points in front of and inside the image of at least ``SEEN_BY_SHARE`` of the cameras (robust
    percentiles, padded), cut to the inner cube; None with too few."""
    seen = sum(_in_view(points, pose, k)[1].astype(np.int64) for pose, k in zip(c2w, _intrinsics(capture), strict=True))
    kept = points[seen >= SEEN_BY_SHARE * len(c2w)]
    if len(kept) < MIN_BOX_POINTS:
        return None
    return _box_from_object_points(kept)


def share_beyond_cameras(capture: Capture, orientation: Orientation) -> float | None:
    """The share of sparse points outside the cube the cameras span about their focus (None without points): photos
    of an object in a room see walls and furniture there."""
    _, points, _ = _upright_centred(capture, orientation)
    if len(points) < MIN_BOX_POINTS:
        return None
    return float((np.abs(points).max(axis=1) > 1.0).mean())
