"""Camera trajectories for novel-view renders: look-at poses, a turntable orbit, the LLFF spiral, resolution scaling.

Pure functions from numbers (or a :class:`Cameras` set) to :class:`Cameras`, all in the OpenGL convention of
``Cameras`` (x right, y up, the camera looking down -z), so a path renders with ``Cameras.generate_rays`` like any
dataset view.
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
    e1 = _normalize(torch.linalg.cross(_fallback_up(up_t), up_t))  # any unit vector perpendicular to up
    if abs(float(up_t[2])) > 0.999:  # z-up: start on +x and turn counter-clockwise seen from above, like Blender
        e1 = torch.tensor([1.0, 0.0, 0.0]) * float(torch.sign(up_t[2]))
    e2 = torch.linalg.cross(up_t, e1)
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


def orbit_from_cameras(cameras: Cameras, n_frames: int, elevation_deg: float | None = None) -> Cameras:
    """An orbit about the world origin matching a dataset's cameras: their mean distance, mean elevation and
    the first camera's intrinsics (NeRF-synthetic cameras all sit on a sphere around the object at the origin)."""
    if len(cameras) == 0:
        raise ValueError("orbit_from_cameras needs at least one camera")
    centers = cameras.centers.float()
    dist = centers.norm(dim=-1).clamp(min=_EPS)
    radius = float(dist.mean())
    if elevation_deg is None:
        elevation_deg = float(torch.rad2deg(torch.asin((centers[:, 2] / dist).clamp(-1.0, 1.0))).mean())
    return orbit_path(
        (0.0, 0.0, 0.0),
        radius,
        elevation_deg,
        n_frames,
        float(cameras.fx[0]),
        float(cameras.fy[0]),
        cameras.width,
        cameras.height,
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


def spiral_path(
    cameras: Cameras,
    n_frames: int,
    near: float,
    far: float,
    n_rotations: float = 2,
    zrate: float = 0.5,
    radius_scale: float = 1.0,
) -> Cameras:
    """The LLFF/NeRF spiral for forward-facing scenes, around the average pose of ``cameras``.

    Radii are the 90th percentile of the cameras' offsets from the average centre, measured in the average pose's
    own axes, so the path stays inside the region the cameras covered (novel views, not extrapolation). Every frame
    looks at the point ``focus_depth(near, far)`` in front of the average pose. Intrinsics are the first camera's.
    """
    _check_frames(n_frames)
    if len(cameras) == 0:
        raise ValueError("spiral_path needs at least one camera")
    avg = average_pose(cameras.camera_to_worlds)
    rotation, center = avg[:, :3], avg[:, 3]
    local = (cameras.centers.float() - center) @ rotation  # offsets in the average camera's axes
    radii = torch.quantile(local.abs(), 0.9, dim=0) * float(radius_scale)
    focus = center - focus_depth(near, far) * rotation[:, 2]  # the camera looks down -z
    up = rotation[:, 1]
    poses = []
    for k in range(n_frames):
        theta = 2.0 * math.pi * n_rotations * k / n_frames
        offset = torch.tensor([math.cos(theta), -math.sin(theta), -math.sin(theta * zrate)]) * radii
        eye = center + rotation @ offset
        poses.append(_view_matrix(eye - focus, up, eye))
    return _cameras(
        torch.stack(poses),
        float(cameras.fx[0]),
        float(cameras.fy[0]),
        float(cameras.cx[0]),
        float(cameras.cy[0]),
        cameras.width,
        cameras.height,
    )


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
