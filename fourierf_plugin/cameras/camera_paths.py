"""Camera trajectories for novel-view renders: look-at poses, a turntable orbit, the LLFF spiral, an arc over the
captured range, a path interpolated through the training cameras, resolution scaling.

Pure functions from numbers (or a :class:`Cameras` set) to :class:`Cameras`, all in the OpenGL convention of
``Cameras`` (x right, y up, the camera looking down -z), so a path renders with ``Cameras.generate_rays`` like any
dataset view. Paths that circle the scene take its centre and up direction (``scene_up``) from the caller, so they
aim at what was photographed rather than at a fixed point.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import torch
from torch import Tensor

from fourierf_plugin.cameras.cameras import Cameras

Vector = Sequence[float] | Tensor

_EPS = 1e-8


def _vec(v: Vector) -> Tensor:
    return torch.as_tensor(v, dtype=torch.float32).reshape(3)


def _normalize(v: Tensor) -> Tensor:
    return v / v.norm().clamp(min=_EPS)


def _fallback_up(forward: Tensor) -> Tensor:
    """A world axis far from ``forward``: the one it is least aligned with."""
    axis = int(forward.abs().argmin())
    up = torch.zeros(3)
    up[axis] = 1.0
    return up


def _view_matrix(backward: Tensor, up: Tensor, position: Tensor) -> Tensor:
    """c2w [3, 4] whose +z column is ``backward`` and whose y column is as close to ``up`` as orthogonality allows.

    When ``up`` is (nearly) parallel to the viewing axis, any perpendicular up is as good as another; a fixed world
    axis is used instead of failing, so a camera straight above the target still gets a valid pose.
    """
    z = _normalize(backward)
    x = torch.linalg.cross(up, z)
    if x.norm() < 1e-6 * max(1.0, float(up.norm())):
        x = torch.linalg.cross(_fallback_up(z), z)
    x = _normalize(x)
    y = torch.linalg.cross(z, x)
    return torch.stack([x, y, z, position], dim=1)


def look_at(eye: Vector, target: Vector, up: Vector = (0.0, 0.0, 1.0)) -> Tensor:
    """OpenGL camera-to-world [3, 4] of a camera at ``eye`` looking at ``target`` with ``up`` roughly upwards."""
    eye_t, target_t = _vec(eye), _vec(target)
    if (eye_t - target_t).norm() < _EPS:
        raise ValueError("look_at needs eye != target")
    return _view_matrix(eye_t - target_t, _vec(up), eye_t)


def _cameras(c2w: Tensor, fx: float, fy: float, cx: float, cy: float, width: int, height: int) -> Cameras:
    n = c2w.shape[0]

    def full(value: float) -> Tensor:
        return torch.full((n,), float(value), dtype=torch.float32)

    return Cameras(c2w.float(), full(fx), full(fy), full(cx), full(cy), int(width), int(height))


def _like_first(cameras: Cameras, c2w: Tensor) -> Cameras:
    """Cameras at ``c2w`` with the first camera's intrinsics and image size."""
    k = cameras
    return _cameras(c2w, float(k.fx[0]), float(k.fy[0]), float(k.cx[0]), float(k.cy[0]), k.width, k.height)


def _check_frames(n_frames: int) -> None:
    if n_frames < 1:
        raise ValueError(f"n_frames must be >= 1, got {n_frames}")


def orbit_path(
    center: Vector,
    radius: float,
    elevation_deg: float,
    n_frames: int,
    fx: float,
    fy: float,
    width: int,
    height: int,
    up: Vector = (0.0, 0.0, 1.0),
    cx: float | None = None,
    cy: float | None = None,
) -> Cameras:
    """A turntable: ``n_frames`` cameras evenly spaced in azimuth around ``up`` through ``center``, all looking at it.

    Elevation is the angle above the plane through ``center`` perpendicular to ``up`` (NeRF-synthetic is z-up, so
    the default orbits the z axis like Blender's turntable). The last frame stops one step short of the first so
    the animation loops without a repeated frame. ``cx``/``cy`` default to the image centre.
    """
    _check_frames(n_frames)
    if radius <= 0:
        raise ValueError(f"radius must be > 0, got {radius}")
    c, up_t = _vec(center), _normalize(_vec(up))
    e1, e2 = _ground_basis(up_t)  # z-up: start on +x and turn counter-clockwise seen from above, like Blender
    elev = math.radians(elevation_deg)
    poses = []
    for k in range(n_frames):
        theta = 2.0 * math.pi * k / n_frames
        offset = math.cos(elev) * (math.cos(theta) * e1 + math.sin(theta) * e2) + math.sin(elev) * up_t
        eye = c + radius * offset
        poses.append(_view_matrix(eye - c, up_t, eye))
    return _cameras(
        torch.stack(poses), fx, fy, width / 2.0 if cx is None else cx, height / 2.0 if cy is None else cy, width, height
    )


UP_SNAP_DEG = 25.0
"""``scene_up`` takes the world axis nearest the cameras' mean up when it lies within this angle of it."""


def scene_up(camera_to_worlds: Tensor) -> Tensor:
    """The scene's up direction: the world axis nearest the cameras' mean up (y) axis when it is close (datasets and
    normalised captures are written with an axis as up, and a few cameras' mean is a noisy estimate of it), else
    that mean itself; +z when the cameras' ups cancel out."""
    mean = camera_to_worlds.float()[:, :, 1].sum(dim=0)
    if mean.norm() < 1e-6 * camera_to_worlds.shape[0]:
        return torch.tensor([0.0, 0.0, 1.0])
    mean = _normalize(mean)
    axis = int(mean.abs().argmax())
    snapped = torch.zeros(3)
    snapped[axis] = float(torch.sign(mean[axis]))
    return snapped if float(mean @ snapped) >= math.cos(math.radians(UP_SNAP_DEG)) else mean


def _ground_basis(up: Tensor) -> tuple[Tensor, Tensor]:
    """Two unit vectors spanning the plane perpendicular to ``up`` (``orbit_path``'s: +x first when z is up)."""
    e1 = _normalize(torch.linalg.cross(_fallback_up(up), up))
    if abs(float(up[2])) > 0.999:
        e1 = torch.tensor([1.0, 0.0, 0.0]) * float(torch.sign(up[2]))
    return e1, torch.linalg.cross(up, e1)


def orbit_from_cameras(
    cameras: Cameras,
    n_frames: int,
    elevation_deg: float | None = None,
    center: Vector = (0.0, 0.0, 0.0),
    up: Vector | None = None,
) -> Cameras:
    """An orbit about ``center`` matching a dataset's cameras: their mean distance from it, their mean elevation
    above the plane through it perpendicular to ``up`` (default ``scene_up``) and the first camera's intrinsics."""
    if len(cameras) == 0:
        raise ValueError("orbit_from_cameras needs at least one camera")
    c = _vec(center)
    up_t = scene_up(cameras.camera_to_worlds) if up is None else _normalize(_vec(up))
    offsets = cameras.centers.float() - c
    dist = offsets.norm(dim=-1).clamp(min=_EPS)
    radius = float(dist.mean())
    if elevation_deg is None:
        elevation_deg = float(torch.rad2deg(torch.asin((offsets @ up_t / dist).clamp(-1.0, 1.0))).mean())
    return orbit_path(
        c,
        radius,
        elevation_deg,
        n_frames,
        float(cameras.fx[0]),
        float(cameras.fy[0]),
        cameras.width,
        cameras.height,
        up=up_t,
        cx=float(cameras.cx[0]),
        cy=float(cameras.cy[0]),
    )


def average_pose(camera_to_worlds: Tensor) -> Tensor:
    """LLFF's mean pose [3, 4]: mean centre, normalised mean viewing (+z) axis, and the mean up (y) axis."""
    c2w = camera_to_worlds.float()
    center = c2w[:, :, 3].mean(dim=0)
    backward = c2w[:, :, 2].sum(dim=0)
    if backward.norm() < 1e-6 * c2w.shape[0]:  # cameras facing every way (a full 360° ring): keep the first's axis
        backward = c2w[0, :, 2]
    up = c2w[:, :, 1].sum(dim=0)
    if up.norm() < 1e-6 * c2w.shape[0]:
        up = c2w[0, :, 1]
    return _view_matrix(backward, _normalize(up), center)


def focus_depth(near: float, far: float, dt: float = 0.75) -> float:
    """LLFF's focus distance: a weighted harmonic mean of the near and far bounds (``dt`` of the way in disparity)."""
    if not 0.0 < near < far:
        raise ValueError(f"need 0 < near < far for the spiral's focus depth, got near={near}, far={far}")
    return 1.0 / ((1.0 - dt) / near + dt / far)


def llff_focus(cameras: Cameras, near: float, far: float) -> Tensor:
    """LLFF's spiral target: the point ``focus_depth(near, far)`` in front of the cameras' average pose."""
    avg = average_pose(cameras.camera_to_worlds)
    return avg[:, 3] - focus_depth(near, far) * avg[:, 2]  # the camera looks down -z


def spiral_path(
    cameras: Cameras,
    n_frames: int,
    target: Vector,
    n_rotations: float = 2,
    zrate: float = 0.5,
    radius_scale: float = 1.0,
) -> Cameras:
    """The LLFF/NeRF spiral around the average pose of ``cameras``, every frame looking at ``target`` (the scene's
    centre; ``llff_focus`` gives LLFF's own).

    Radii are the 90th percentile of the cameras' offsets from the average centre, measured in the average pose's
    own axes, so the path stays inside the region the cameras covered (novel views, not extrapolation). Intrinsics
    are the first camera's.
    """
    _check_frames(n_frames)
    if len(cameras) == 0:
        raise ValueError("spiral_path needs at least one camera")
    avg = average_pose(cameras.camera_to_worlds)
    rotation, center = avg[:, :3], avg[:, 3]
    local = (cameras.centers.float() - center) @ rotation  # offsets in the average camera's axes
    radii = torch.quantile(local.abs(), 0.9, dim=0) * float(radius_scale)
    focus = _vec(target)
    if (focus - center).norm() < _EPS:
        raise ValueError("the spiral's target must not be the cameras' average centre")
    up = rotation[:, 1]
    poses = []
    for k in range(n_frames):
        theta = 2.0 * math.pi * n_rotations * k / n_frames
        offset = torch.tensor([math.cos(theta), -math.sin(theta), -math.sin(theta * zrate)]) * radii
        eye = center + rotation @ offset
        poses.append(_view_matrix(eye - focus, up, eye))
    return _like_first(cameras, torch.stack(poses))


def azimuths(centers: Tensor, center: Vector, up: Vector) -> Tensor:
    """Angles [N] (radians, in (-pi, pi]) of camera centres about the axis through ``center`` along ``up``, in the
    ground basis ``orbit_path`` uses."""
    up_t = _normalize(_vec(up))
    e1, e2 = _ground_basis(up_t)
    offsets = centers.float() - _vec(center)
    return torch.atan2(offsets @ e2, offsets @ e1)


def captured_range(centers: Tensor, center: Vector, up: Vector) -> tuple[float, float]:
    """(start, span) in radians: the smallest arc about the axis that holds every camera, from one end of it;
    everything but the widest empty gap between cameras seen from the centre."""
    angles = torch.sort(azimuths(centers, center, up).double()).values
    if angles.numel() < 2:
        return float(angles[0]), 0.0
    gaps = torch.remainder(torch.roll(angles, -1) - angles, 2 * math.pi)
    gaps[-1] = 2 * math.pi - float(angles[-1] - angles[0])  # from the last back round to the first
    widest = int(gaps.argmax())
    start = float(angles[(widest + 1) % angles.numel()])
    return start, 2 * math.pi - float(gaps[widest])


def surrounds(centers: Tensor, center: Vector, up: Vector) -> bool:
    """Whether the cameras are all around the scene: no half-turn about its axis is empty of cameras."""
    return captured_range(centers, center, up)[1] > math.pi


def arc_path(
    cameras: Cameras, center: Vector, n_frames: int, up: Vector | None = None, span_scale: float = 1.0
) -> Cameras:
    """Cameras sweeping the angular range the dataset's cameras cover about ``center`` (``captured_range``), from
    one end to the other, at their mean horizontal distance and mean height, all looking at ``center``; the first
    camera's intrinsics. ``span_scale`` shrinks or widens the sweep about its middle.

    Why not a full orbit: a capture over part of a circle has seen nothing of the rest.
    """
    _check_frames(n_frames)
    if len(cameras) == 0:
        raise ValueError("arc_path needs at least one camera")
    c = _vec(center)
    up_t = scene_up(cameras.camera_to_worlds) if up is None else _normalize(_vec(up))
    offsets = cameras.centers.float() - c
    height = offsets @ up_t
    radius = float((offsets - height[:, None] * up_t).norm(dim=-1).mean())
    if radius < _EPS:
        raise ValueError("the cameras lie on the arc's axis: there is no arc to sweep")
    start, span = captured_range(cameras.centers, c, up_t)
    middle, span = start + span / 2, span * float(span_scale)
    e1, e2 = _ground_basis(up_t)
    steps = [0.5] if n_frames == 1 else [k / (n_frames - 1) for k in range(n_frames)]
    poses = []
    for fraction in steps:
        theta = middle + span * (fraction - 0.5)
        eye = c + radius * (math.cos(theta) * e1 + math.sin(theta) * e2) + float(height.mean()) * up_t
        poses.append(_view_matrix(eye - c, up_t, eye))
    return _like_first(cameras, torch.stack(poses))


def capture_order(centers: Tensor) -> list[int]:
    """The cameras in the order a photographer walked them: the shortest of the greedy nearest-neighbour paths
    (one from each camera), so the path runs from one end of the capture to the other."""
    points = centers.double()
    n = points.shape[0]
    if n < 3:
        return list(range(n))
    dist = torch.cdist(points, points)
    best: tuple[float, list[int]] | None = None
    for first in range(n):
        order, left, length = [first], set(range(n)) - {first}, 0.0
        while left:
            last = order[-1]
            nearest = min(left, key=lambda j, last=last: (float(dist[last, j]), j))
            length += float(dist[last, nearest])
            order.append(nearest)
            left.remove(nearest)
        if best is None or length < best[0] - 1e-12:
            best = (length, order)
    assert best is not None
    return best[1]


def _quaternion(rotation: Tensor) -> Tensor:
    """Unit quaternion (w, x, y, z) of a [3, 3] rotation (Shepperd's method: the largest of the four first)."""
    r = rotation.double()
    trace = float(r[0, 0] + r[1, 1] + r[2, 2])
    options = [trace, float(r[0, 0]), float(r[1, 1]), float(r[2, 2])]
    k = max(range(4), key=lambda i: options[i])
    if k == 0:
        s = 2.0 * math.sqrt(max(1.0 + trace, 0.0))
        q = [s / 4, (r[2, 1] - r[1, 2]) / s, (r[0, 2] - r[2, 0]) / s, (r[1, 0] - r[0, 1]) / s]
    elif k == 1:
        s = 2.0 * math.sqrt(max(1.0 + r[0, 0] - r[1, 1] - r[2, 2], 0.0))
        q = [(r[2, 1] - r[1, 2]) / s, s / 4, (r[0, 1] + r[1, 0]) / s, (r[0, 2] + r[2, 0]) / s]
    elif k == 2:
        s = 2.0 * math.sqrt(max(1.0 - r[0, 0] + r[1, 1] - r[2, 2], 0.0))
        q = [(r[0, 2] - r[2, 0]) / s, (r[0, 1] + r[1, 0]) / s, s / 4, (r[1, 2] + r[2, 1]) / s]
    else:
        s = 2.0 * math.sqrt(max(1.0 - r[0, 0] - r[1, 1] + r[2, 2], 0.0))
        q = [(r[1, 0] - r[0, 1]) / s, (r[0, 2] + r[2, 0]) / s, (r[1, 2] + r[2, 1]) / s, s / 4]
    out = torch.tensor([float(v) for v in q], dtype=torch.float64)
    return out / out.norm()


def _rotation(q: Tensor) -> Tensor:
    w, x, y, z = (float(v) for v in q / q.norm())
    return torch.tensor(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
            [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
            [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
        ],
        dtype=torch.float64,
    )


def slerp(q0: Tensor, q1: Tensor, t: float) -> Tensor:
    """Spherical interpolation of unit quaternions along the shorter way round (constant angular speed)."""
    dot = float(q0 @ q1)
    if dot < 0:
        q1, dot = -q1, -dot
    if dot > 1.0 - 1e-9:
        q = q0 + t * (q1 - q0)
        return q / q.norm()
    angle = math.acos(min(dot, 1.0))
    return (math.sin((1 - t) * angle) * q0 + math.sin(t * angle) * q1) / math.sin(angle)


def interpolate_path(cameras: Cameras, steps_per_transition: int = 10, order: bool = True) -> Cameras:
    """A path through the cameras (nerfstudio's ``interpolate``): between consecutive ones, positions and
    intrinsics move linearly and rotations by ``slerp``, ``steps_per_transition`` frames a transition; frame
    ``k * steps_per_transition`` is the k-th camera exactly. ``order`` first sorts them along the capture
    (``capture_order``); otherwise they are taken as given. Rendered without lens distortion."""
    if steps_per_transition < 1:
        raise ValueError(f"steps_per_transition must be >= 1, got {steps_per_transition}")
    if len(cameras) == 0:
        raise ValueError("interpolate_path needs at least one camera")
    ids = capture_order(cameras.centers) if order else list(range(len(cameras)))
    c2w = cameras.camera_to_worlds.double()[ids]
    intrinsics = torch.stack([cameras.fx, cameras.fy, cameras.cx, cameras.cy], dim=1).double()[ids]
    quats = [_quaternion(m[:, :3]) for m in c2w]
    poses, values = [c2w[0]], [intrinsics[0]]
    for k in range(1, len(ids)):
        for step in range(1, steps_per_transition + 1):
            if step == steps_per_transition:  # the next camera itself, not a round trip through a quaternion
                poses.append(c2w[k])
                values.append(intrinsics[k])
                continue
            t = step / steps_per_transition
            rotation = _rotation(slerp(quats[k - 1], quats[k], t))
            position = (1 - t) * c2w[k - 1][:, 3] + t * c2w[k][:, 3]
            poses.append(torch.cat([rotation, position[:, None]], dim=1))
            values.append((1 - t) * intrinsics[k - 1] + t * intrinsics[k])
    fx, fy, cx, cy = torch.stack(values).float().unbind(dim=1)
    return Cameras(torch.stack(poses).float(), fx, fy, cx, cy, cameras.width, cameras.height)


def scale_cameras(cameras: Cameras, factor: float) -> Cameras:
    """The same cameras at ``factor`` times the resolution (sizes rounded, at least 1 pixel).

    Intrinsics scale by the ratio of the rounded sizes, per axis, so the scaled image covers exactly the original
    field of view even when ``width * factor`` is not a whole number.
    """
    if not factor > 0:
        raise ValueError(f"the resolution scale must be > 0, got {factor}")
    width = max(1, round(cameras.width * factor))
    height = max(1, round(cameras.height * factor))
    sx, sy = width / cameras.width, height / cameras.height
    return Cameras(
        cameras.camera_to_worlds.clone(),
        cameras.fx * sx,
        cameras.fy * sy,
        cameras.cx * sx,
        cameras.cy * sy,
        width,
        height,
        cameras.camera_model,  # the lens acts on normalised coordinates: the same at any resolution
        None if cameras.distortion is None else cameras.distortion.clone(),
    )
