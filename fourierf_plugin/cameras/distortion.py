"""Lens distortion on normalised image coordinates: the forward models and their inverses.

Coordinates follow OpenCV: ``x = (u - cx) / fx``, ``y = (v - cy) / fy`` with y pointing down. Why here and on
rays: a photo capture (COLMAP, nerfstudio's ``transforms.json``) describes its lens with these models, and
training on the photos as they are needs the ray of each *distorted* pixel; undistorting the coordinates before
forming the ray does that without resampling (and blurring) the images.

Models (COLMAP / nerfstudio names; coefficients always in nerfstudio's order (k1, k2, k3, k4, p1, p2)):

- ``PINHOLE``, ``SIMPLE_PINHOLE``: no distortion (all coefficients must be zero).
- ``OPENCV``: radial-tangential, OpenCV's formula with radial factor ``1 + k1 r^2 + k2 r^4 + k3 r^6``; a non-zero
  k4 adds ``k4 r^8`` as nerfstudio's OPENCV does (OpenCV itself has no k4 in this model).
- ``OPENCV_FISHEYE``: equidistant, ``theta_d = theta (1 + k1 t^2 + k2 t^4 + k3 t^6 + k4 t^8)`` with
  ``t = theta`` the angle from the optical axis; p1 and p2 must be zero.

Everything runs in float64 (Newton's method needs it to reach 1e-6 px) and returns the input's floating dtype.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Literal, get_args

import torch
from torch import Tensor

CameraModel = Literal["PINHOLE", "SIMPLE_PINHOLE", "OPENCV", "OPENCV_FISHEYE"]
CAMERA_MODELS: tuple[str, ...] = get_args(CameraModel)
DISTORTION_KEYS: tuple[str, ...] = ("k1", "k2", "k3", "k4", "p1", "p2")
"""nerfstudio's order of the distortion coefficients (the last axis of every ``coeffs`` here)."""

_USED_KEYS: dict[str, tuple[str, ...]] = {
    "PINHOLE": (),
    "SIMPLE_PINHOLE": (),
    "OPENCV": DISTORTION_KEYS,
    "OPENCV_FISHEYE": ("k1", "k2", "k3", "k4"),
}

DEFAULT_ITERATIONS = 20
"""Newton steps allowed; realistic lenses converge in 3-6 (quadratic convergence from the distorted point)."""
DEFAULT_TOLERANCE = 1e-12
"""Largest residual accepted, in normalised coordinates (1e-8 px even at a focal length of 10^4 px)."""

Coefficients = Tensor | Sequence[float]


def check_camera_model(model: str) -> None:
    """ValueError unless ``model`` is one of :data:`CAMERA_MODELS`."""
    if model not in CAMERA_MODELS:
        raise ValueError(f"unknown camera model {model!r}: expected one of {', '.join(CAMERA_MODELS)}")


def has_distortion(coeffs: Coefficients | None, model: str) -> bool:
    """Whether ``model`` with ``coeffs`` differs from an ideal pinhole.

    False for the pinhole models and for OPENCV with all-zero (or no) coefficients; always True for
    OPENCV_FISHEYE, whose equidistant projection (r = theta) bends rays even with every coefficient zero.
    """
    check_camera_model(model)
    if model == "OPENCV_FISHEYE":
        return True
    if coeffs is None or not _USED_KEYS[model]:
        return False
    return bool(torch.as_tensor(coeffs).ne(0).any())


def check_coefficients(coeffs: Coefficients, model: str) -> None:
    """ValueError unless ``coeffs`` is [..., 6], finite, and zero wherever ``model`` does not use a coefficient.

    Why: a non-zero coefficient the model ignores (k1 of a PINHOLE, p1 of a fisheye) means the model name and the
    coefficients disagree; ignoring it silently would form the wrong rays.
    """
    check_camera_model(model)
    k = torch.as_tensor(coeffs)
    _check_shape(k)
    if not bool(torch.isfinite(k).all()):
        raise ValueError(f"distortion coefficients must be finite, got {k.tolist() if k.numel() <= 12 else 'NaN/inf'}")
    unused = [
        key for i, key in enumerate(DISTORTION_KEYS) if key not in _USED_KEYS[model] and bool(k[..., i].ne(0).any())
    ]
    if unused:
        raise ValueError(f"camera model {model} does not use {', '.join(unused)}, but they are non-zero")


def _check_shape(k: Tensor) -> None:
    if k.ndim == 0 or k.shape[-1] != len(DISTORTION_KEYS):
        raise ValueError(
            f"distortion coefficients must have a last axis of {len(DISTORTION_KEYS)} "
            f"({', '.join(DISTORTION_KEYS)}), got shape {tuple(k.shape)}"
        )


def _prepare(x: Tensor, y: Tensor, coeffs: Coefficients, model: str) -> tuple[Tensor, Tensor, list[Tensor]]:
    """Checked float64 coordinates and the six coefficients, each broadcastable against the points."""
    check_camera_model(model)
    x, y = torch.as_tensor(x), torch.as_tensor(y)
    if x.shape != y.shape:
        raise ValueError(f"x and y must have the same shape, got {tuple(x.shape)} and {tuple(y.shape)}")
    k = torch.as_tensor(coeffs, dtype=torch.float64, device=x.device)
    _check_shape(k)
    try:
        batch = torch.broadcast_shapes(k.shape[:-1], x.shape)
    except RuntimeError:
        batch = None
    if batch != x.shape:
        raise ValueError(
            f"distortion coefficients of shape {tuple(k.shape)} do not broadcast over points of shape "
            f"{tuple(x.shape)}: pass one set [6] or one per point [..., 6]"
        )
    check_coefficients(k, model)
    return x.to(torch.float64), y.to(torch.float64), list(k.unbind(-1))


def _out_dtype(x: Tensor) -> torch.dtype:
    x = torch.as_tensor(x)
    return x.dtype if x.is_floating_point() else torch.get_default_dtype()


def _safe_radius(r2: Tensor) -> tuple[Tensor, Tensor]:
    """sqrt(r2) where r2 > 0 (1 elsewhere, so neither the value nor its gradient is NaN at the centre), the mask."""
    positive = r2 > 0
    return torch.sqrt(torch.where(positive, r2, torch.ones_like(r2))), positive


# -- OPENCV (radial-tangential) -------------------------------------------------------------------------------------
def _radial(r2: Tensor, k: list[Tensor]) -> Tensor:
    """OPENCV's radial factor 1 + k1 r^2 + k2 r^4 + k3 r^6 (+ k4 r^8)."""
    k1, k2, k3, k4 = k[:4]
    return 1 + r2 * (k1 + r2 * (k2 + r2 * (k3 + r2 * k4)))


def _opencv(x: Tensor, y: Tensor, k: list[Tensor]) -> tuple[Tensor, Tensor, Tensor, Tensor, Tensor, Tensor]:
    """Distorted point and its 2x2 Jacobian (d xd/dx, d xd/dy, d yd/dx, d yd/dy)."""
    k1, k2, k3, k4, p1, p2 = k
    r2 = x * x + y * y
    radial = _radial(r2, k)
    d_radial = k1 + r2 * (2 * k2 + r2 * (3 * k3 + r2 * 4 * k4))  # d radial / d r2
    xd = x * radial + 2 * p1 * x * y + p2 * (r2 + 2 * x * x)
    yd = y * radial + p1 * (r2 + 2 * y * y) + 2 * p2 * x * y
    cross = 2 * x * y * d_radial + 2 * p1 * x + 2 * p2 * y  # d xd/dy = d yd/dx
    dxd_dx = radial + 2 * x * x * d_radial + 2 * p1 * y + 6 * p2 * x
    dyd_dy = radial + 2 * y * y * d_radial + 6 * p1 * y + 2 * p2 * x
    return xd, yd, dxd_dx, cross, cross, dyd_dy


def _undistort_opencv(
    xd: Tensor, yd: Tensor, k: list[Tensor], iterations: int, tolerance: float
) -> tuple[Tensor, Tensor]:
    """Newton's method on distort(x, y) = (xd, yd), starting from the distorted point."""
    x, y = xd, yd
    for step in range(iterations + 1):
        fx, fy, a, b, c, d = _opencv(x, y, k)
        rx, ry = fx - xd, fy - yd
        det = a * d - b * c
        if _converged(torch.maximum(rx.abs(), ry.abs()), tolerance, step, iterations, "OPENCV"):
            break
        x = x - (d * rx - b * ry) / det
        y = y - (a * ry - c * rx) / det
    # Past the fold the radial factor can turn negative too (a mirrored point, with det > 0 again).
    _check_unfolded(torch.minimum(det, _radial(x * x + y * y, k)), "OPENCV")
    return x, y


def _check_unfolded(jacobian: Tensor, model: str) -> None:
    """ValueError where a solution lies beyond the lens's fold (where distortion reverses: ``jacobian`` <= 0).

    Past the fold a distortion polynomial comes back: a point there also maps onto the image, but no real lens
    images it (it would appear mirrored); such a pixel lies outside the region the coefficients describe.
    """
    folded = ~(jacobian > 0)
    if bool(folded.any()):
        raise ValueError(
            f"{model} undistortion: {int(folded.sum())} of {jacobian.numel()} points lie beyond the fold of the "
            "lens model (where the distortion turns back on itself), so the distortion is not invertible there: "
            "usually coefficients estimated from too few points, or intrinsics that belong to another image size"
        )


# -- OPENCV_FISHEYE (equidistant) -----------------------------------------------------------------------------------
def _theta_distorted(theta: Tensor, k: list[Tensor]) -> tuple[Tensor, Tensor]:
    """theta_d(theta) and its derivative."""
    k1, k2, k3, k4 = k[:4]
    t2 = theta * theta
    poly = 1 + t2 * (k1 + t2 * (k2 + t2 * (k3 + t2 * k4)))
    slope = 1 + t2 * (3 * k1 + t2 * (5 * k2 + t2 * (7 * k3 + t2 * 9 * k4)))
    return theta * poly, slope


def _fisheye_theta(xd: Tensor, yd: Tensor, k: list[Tensor], iterations: int, tolerance: float) -> tuple[Tensor, ...]:
    """Angle from the axis of each distorted point (Newton on theta_d(theta) = |(xd, yd)|), its radius and mask."""
    rd, positive = _safe_radius(xd * xd + yd * yd)
    theta_d = torch.where(positive, rd, torch.zeros_like(rd))
    theta = theta_d
    for step in range(iterations + 1):
        value, slope = _theta_distorted(theta, k)
        residual = value - theta_d
        if _converged(residual.abs(), tolerance, step, iterations, "OPENCV_FISHEYE"):
            break
        theta = theta - residual / slope
    _check_unfolded(slope, "OPENCV_FISHEYE")
    if bool(((theta < 0) | (theta >= math.pi)).any()):
        raise ValueError(
            "fisheye undistortion found angles outside [0, pi) from the optical axis: the coefficients are not "
            "invertible over these points (check k1..k4, and that the intrinsics belong to this image size)"
        )
    return theta, rd, positive


def _converged(residual: Tensor, tolerance: float, step: int, iterations: int, model: str) -> bool:
    """True once every residual is within ``tolerance``; ValueError when the last step is spent (or NaN appears)."""
    ok = residual <= tolerance  # NaN compares False: a singular Jacobian is reported, not returned
    if bool(ok.all()):
        return True
    if step == iterations:
        bad = ~ok
        worst = float(residual[bad].nan_to_num(nan=math.inf).max())
        raise ValueError(
            f"{model} undistortion did not converge for {int(bad.sum())} of {residual.numel()} points in "
            f"{iterations} Newton steps (worst residual {worst:.3g} in normalised units): the distortion is not "
            "invertible there, usually coefficients estimated from too few points or intrinsics that belong to "
            "another image size"
        )
    return False


# -- public functions -----------------------------------------------------------------------------------------------
def distort(x: Tensor, y: Tensor, coeffs: Coefficients, model: str) -> tuple[Tensor, Tensor]:
    """Where the lens puts the ideal pinhole point (x, y): the distorted normalised coordinates (xd, yd).

    ``coeffs`` is [6] (shared) or [..., 6] (one set per point, broadcast over the points' shape).
    """
    out = _out_dtype(x)
    x, y, k = _prepare(x, y, coeffs, model)
    if model in ("PINHOLE", "SIMPLE_PINHOLE"):
        return x.to(out), y.to(out)
    if model == "OPENCV":
        xd, yd = _opencv(x, y, k)[:2]
        return xd.to(out), yd.to(out)
    r, positive = _safe_radius(x * x + y * y)
    theta_d = _theta_distorted(torch.atan(r), k)[0]
    scale = torch.where(positive, theta_d / r, torch.ones_like(r))  # -> 1 at the centre
    return (x * scale).to(out), (y * scale).to(out)


def _undistort64(
    xd: Tensor, yd: Tensor, k: list[Tensor], model: str, iterations: int, tolerance: float
) -> tuple[Tensor, Tensor]:
    """:func:`undistort` on checked float64 inputs, in float64."""
    if model in ("PINHOLE", "SIMPLE_PINHOLE"):
        return xd, yd
    if model == "OPENCV":
        return _undistort_opencv(xd, yd, k, iterations, tolerance)
    theta, rd, positive = _fisheye_theta(xd, yd, k, iterations, tolerance)
    if bool((theta >= math.pi / 2).any()):
        raise ValueError(
            "fisheye points 90° or more from the optical axis have no pinhole coordinates; "
            "use undistorted_directions for fields of view over 180°"
        )
    scale = torch.where(positive, torch.tan(theta) / rd, torch.ones_like(rd))  # -> 1 at the centre
    return xd * scale, yd * scale


def undistort(
    xd: Tensor,
    yd: Tensor,
    coeffs: Coefficients,
    model: str,
    iterations: int = DEFAULT_ITERATIONS,
    tolerance: float = DEFAULT_TOLERANCE,
) -> tuple[Tensor, Tensor]:
    """The ideal pinhole point (x, y) that the lens moves to (xd, yd): the inverse of :func:`distort`.

    Newton's method from the distorted point, stopping once every residual is within ``tolerance``; a ValueError
    when it does not converge in ``iterations`` steps (a lens model that is not invertible there). A fisheye
    point 90° or more from the axis has no pinhole coordinates (ValueError): use :func:`undistorted_directions`.
    """
    out = _out_dtype(xd)
    x, y = _undistort64(*_prepare(xd, yd, coeffs, model), model, iterations, tolerance)
    return x.to(out), y.to(out)


def undistorted_directions(
    xd: Tensor,
    yd: Tensor,
    coeffs: Coefficients,
    model: str,
    iterations: int = DEFAULT_ITERATIONS,
    tolerance: float = DEFAULT_TOLERANCE,
) -> Tensor:
    """Unit ray directions [..., 3] in the OpenCV camera frame (x right, y down, z forward) of distorted points.

    Same as normalising (x, y, 1) of :func:`undistort`, and also defined for fisheye rays beyond 90° (z <= 0).
    """
    out = _out_dtype(xd)
    xd, yd, k = _prepare(xd, yd, coeffs, model)
    if model == "OPENCV_FISHEYE":
        theta, rd, positive = _fisheye_theta(xd, yd, k, iterations, tolerance)
        scale = torch.where(positive, torch.sin(theta) / rd, torch.ones_like(rd))  # -> 1 at the centre
        return torch.stack([xd * scale, yd * scale, torch.cos(theta)], dim=-1).to(out)
    x, y = _undistort64(xd, yd, k, model, iterations, tolerance)
    directions = torch.stack([x, y, torch.ones_like(x)], dim=-1)
    return (directions / directions.norm(dim=-1, keepdim=True)).to(out)
