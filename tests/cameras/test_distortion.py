"""Lens distortion: round trips over whole images, closed-form cases, the Newton solver's limits, and input checks."""

from __future__ import annotations

import math

import pytest
import torch

from fourierf_plugin.cameras.distortion import (
    CAMERA_MODELS,
    DISTORTION_KEYS,
    _opencv,
    distort,
    has_distortion,
    undistort,
    undistorted_directions,
)

WIDTH, HEIGHT, FOCAL = 640, 480, 500.0
# (k1, k2, k3, k4, p1, p2): a phone's barrel lens with a little decentring, and an equidistant fisheye lens.
PHONE = (-0.12, 0.03, -0.004, 0.0, 1e-3, -5e-4)
FISHEYE = (0.05, -0.01, 0.002, -0.0005, 0.0, 0.0)
LENSES = [("OPENCV", PHONE), ("OPENCV_FISHEYE", FISHEYE)]


def pixel_grid(width: int = WIDTH, height: int = HEIGHT, focal: float = FOCAL) -> tuple[torch.Tensor, torch.Tensor]:
    """Normalised coordinates [H, W] of every pixel centre of an image with its principal point in the middle."""
    v, u = torch.meshgrid(
        torch.arange(height, dtype=torch.float64) + 0.5, torch.arange(width, dtype=torch.float64) + 0.5, indexing="ij"
    )
    return (u - width / 2) / focal, (v - height / 2) / focal


def max_px(a: torch.Tensor, b: torch.Tensor) -> float:
    return float((a - b).abs().max()) * FOCAL


@pytest.mark.parametrize(("model", "coeffs"), LENSES)
def test_round_trips_over_every_pixel_to_a_micro_pixel(model: str, coeffs: tuple[float, ...]) -> None:
    xd, yd = pixel_grid()
    x, y = undistort(xd, yd, coeffs, model)
    back_x, back_y = distort(x, y, coeffs, model)
    assert max(max_px(back_x, xd), max_px(back_y, yd)) < 1e-6
    # The other way round: ideal points through the lens and back.
    dx, dy = distort(xd, yd, coeffs, model)
    x2, y2 = undistort(dx, dy, coeffs, model)
    assert max(max_px(x2, xd), max_px(y2, yd)) < 1e-6
    # The lens really moves the corners (several pixels), so the round trip is not trivially the identity.
    assert max_px(x, xd) > 5.0


def test_per_point_coefficients_equal_one_call_per_lens() -> None:
    xd, yd = pixel_grid(8, 6)
    lenses = torch.tensor([PHONE, (0.1, 0.0, 0.0, 0.0, 0.0, 0.0), (0.0, 0.0, 0.0, 0.0, -2e-3, 1e-3)])
    per_point = lenses[torch.arange(xd.numel()) % 3].reshape(*xd.shape, 6)
    x, y = undistort(xd, yd, per_point, "OPENCV")
    for i, lens in enumerate(lenses):
        mask = (torch.arange(xd.numel()) % 3 == i).reshape(xd.shape)
        xi, yi = undistort(xd[mask], yd[mask], lens, "OPENCV")
        torch.testing.assert_close(x[mask], xi, rtol=0, atol=1e-15)
        torch.testing.assert_close(y[mask], yi, rtol=0, atol=1e-15)


@pytest.mark.parametrize("model", CAMERA_MODELS[:3])
def test_zero_coefficients_of_pinhole_and_opencv_are_the_identity(model: str) -> None:
    xd, yd = pixel_grid(16, 12)
    zeros = torch.zeros(6, dtype=torch.float64)
    for fn in (distort, undistort):
        x, y = fn(xd, yd, zeros, model)
        assert torch.equal(x, xd) and torch.equal(y, yd)
    assert not has_distortion(zeros, model)


def test_pure_k1_scales_the_radius_by_one_plus_k1_r2() -> None:
    g = torch.Generator().manual_seed(0)
    x, y = (torch.rand(2, 100, generator=g, dtype=torch.float64) - 0.5).unbind()
    k1 = -0.2
    xd, yd = distort(x, y, (k1, 0, 0, 0, 0, 0), "OPENCV")
    r = torch.hypot(x, y)
    torch.testing.assert_close(torch.hypot(xd, yd), r * (1 + k1 * r**2), rtol=1e-15, atol=0)
    torch.testing.assert_close(torch.atan2(yd, xd), torch.atan2(y, x), rtol=0, atol=1e-15)  # radial: same direction


def test_pure_tangential_distortion_on_the_x_axis() -> None:
    """OpenCV's tangential terms at (x, 0): x_d = x + 3 p2 x^2 and y_d = p1 x^2."""
    x = torch.tensor([0.1, -0.3, 0.5], dtype=torch.float64)
    p1, p2 = 2e-3, -1e-3
    xd, yd = distort(x, torch.zeros_like(x), (0, 0, 0, 0, p1, p2), "OPENCV")
    torch.testing.assert_close(xd, x + 3 * p2 * x**2, rtol=1e-15, atol=0)
    torch.testing.assert_close(yd, p1 * x**2, rtol=1e-15, atol=0)


def test_k4_adds_the_r8_term_as_nerfstudio_does() -> None:
    x, y = torch.tensor([0.6], dtype=torch.float64), torch.tensor([0.0], dtype=torch.float64)
    xd, _ = distort(x, y, (0, 0, 0, 0.5, 0, 0), "OPENCV")
    torch.testing.assert_close(xd, x * (1 + 0.5 * 0.6**8), rtol=1e-15, atol=0)


def test_fisheye_maps_the_angle_from_the_axis_by_the_polynomial() -> None:
    """A pinhole point at r = tan(theta) lands at r_d = theta (1 + k1 theta^2 + ...); zero coefficients: r_d = theta."""
    theta = torch.tensor([0.0, 0.1, math.pi / 4, 1.2], dtype=torch.float64)
    x, y = torch.tan(theta) * math.cos(0.7), torch.tan(theta) * math.sin(0.7)
    k1, k2, k3, k4 = FISHEYE[:4]
    expected = theta * (1 + k1 * theta**2 + k2 * theta**4 + k3 * theta**6 + k4 * theta**8)
    xd, yd = distort(x, y, FISHEYE, "OPENCV_FISHEYE")
    torch.testing.assert_close(torch.hypot(xd, yd), expected, rtol=1e-14, atol=0)
    xd0, yd0 = distort(x, y, torch.zeros(6), "OPENCV_FISHEYE")
    torch.testing.assert_close(torch.hypot(xd0, yd0), theta, rtol=1e-14, atol=0)
    assert has_distortion(None, "OPENCV_FISHEYE")  # equidistant bends rays even without coefficients


def test_fisheye_directions_reach_beyond_ninety_degrees() -> None:
    """Equidistant with zero coefficients: the point at r_d = theta is the ray at theta from the axis, even > 90°."""
    theta = torch.tensor([0.3, math.pi / 2, 2.0], dtype=torch.float64)
    d = undistorted_directions(theta, torch.zeros_like(theta), torch.zeros(6), "OPENCV_FISHEYE")
    expected = torch.stack([torch.sin(theta), torch.zeros_like(theta), torch.cos(theta)], dim=-1)
    torch.testing.assert_close(d, expected, rtol=0, atol=1e-15)
    with pytest.raises(ValueError, match="90° or more"):
        undistort(theta, torch.zeros_like(theta), torch.zeros(6), "OPENCV_FISHEYE")


@pytest.mark.parametrize("model", ["PINHOLE", "OPENCV"])
def test_directions_are_the_normalised_undistorted_points(model: str) -> None:
    xd, yd = pixel_grid(16, 12, focal=10.0)
    coeffs = PHONE if model == "OPENCV" else (0.0,) * 6
    d = undistorted_directions(xd, yd, coeffs, model)
    x, y = undistort(xd, yd, coeffs, model)
    torch.testing.assert_close(d[..., :2] / d[..., 2:], torch.stack([x, y], dim=-1), rtol=0, atol=1e-14)
    torch.testing.assert_close(d.norm(dim=-1), torch.ones_like(x), rtol=0, atol=1e-15)


@pytest.mark.parametrize(("model", "coeffs"), LENSES)
def test_gradients_at_the_centre_are_finite_and_the_identity(model: str, coeffs: tuple[float, ...]) -> None:
    for fn in (distort, undistort):
        point = torch.zeros(2, dtype=torch.float64, requires_grad=True)
        jacobian = torch.stack([g.reshape(()) for g in fn(point[0:1], point[1:2], coeffs, model)])
        rows = [torch.autograd.grad(jacobian[i], point, retain_graph=True)[0] for i in range(2)]
        torch.testing.assert_close(torch.stack(rows), torch.eye(2, dtype=torch.float64), rtol=0, atol=1e-15)
    d = undistorted_directions(torch.zeros(1), torch.zeros(1), coeffs, model)
    torch.testing.assert_close(d, torch.tensor([[0.0, 0.0, 1.0]]))


def test_the_newton_jacobian_is_the_derivative_of_the_distortion() -> None:
    k = list(torch.tensor((-0.3, 0.1, -0.02, 0.01, 3e-3, -2e-3), dtype=torch.float64).unbind())
    for x0, y0 in [(0.3, -0.2), (-0.5, 0.4), (0.05, 0.6)]:
        point = torch.tensor([x0, y0], dtype=torch.float64)
        numeric = torch.autograd.functional.jacobian(lambda p: torch.stack(_opencv(p[0], p[1], k)[:2]), point)
        analytic = torch.stack(_opencv(point[0], point[1], k)[2:]).reshape(2, 2)
        torch.testing.assert_close(analytic, numeric, rtol=1e-13, atol=1e-14)


def test_newton_stops_at_the_iteration_limit_with_a_clear_error() -> None:
    xd, yd = pixel_grid(64, 48, focal=40.0)  # corners at r ~ 1: strong distortion there
    strong = (-0.3, 0.1, 0.0, 0.0, 0.0, 0.0)
    undistort(xd, yd, strong, "OPENCV")  # the default limit converges
    with pytest.raises(ValueError, match=r"did not converge for \d+ of 3072 points in 2 Newton steps"):
        undistort(xd, yd, strong, "OPENCV", iterations=2)


@pytest.mark.parametrize("model", ["OPENCV", "OPENCV_FISHEYE"])
def test_a_lens_that_cannot_reach_a_point_is_reported_not_returned(model: str) -> None:
    """r (1 - r^2) never exceeds 2 / (3 sqrt 3) ≈ 0.385 (theta (1 - theta^2) likewise): nothing is imaged at 0.6.

    Newton does find x ≈ -1.23 for OPENCV, whose mirror image lands there; that is beyond the lens's fold.
    """
    with pytest.raises(ValueError, match="not invertible"):
        undistort(torch.tensor([0.6]), torch.tensor([0.0]), (-1.0, 0, 0, 0, 0, 0), model)


def test_float32_in_float32_out_computed_in_float64() -> None:
    xd, yd = pixel_grid(32, 24, focal=30.0)
    x64, _ = undistort(xd, yd, PHONE, "OPENCV")
    x32, y32 = undistort(xd.float(), yd.float(), PHONE, "OPENCV")
    assert x32.dtype == y32.dtype == torch.float32
    torch.testing.assert_close(x32.double(), x64, rtol=0, atol=1e-6)


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (([0.1], [0.2], PHONE, "RADIAL"), "unknown camera model 'RADIAL'"),
        (([0.1], [0.2], PHONE[:5], "OPENCV"), r"last axis of 6 \(k1, k2, k3, k4, p1, p2\), got shape \(5,\)"),
        (([0.1, 0.2], [0.2, 0.1], [PHONE] * 3, "OPENCV"), r"shape \(3, 6\) do not broadcast over points of shape"),
        (([0.1], [0.2, 0.3], PHONE, "OPENCV"), "same shape"),
        (([0.1], [0.2], (0.1, 0, 0, 0, 0, 0), "PINHOLE"), "PINHOLE does not use k1"),
        (([0.1], [0.2], (0.1, 0, 0, 0, 1e-3, 0), "OPENCV_FISHEYE"), "OPENCV_FISHEYE does not use p1"),
        (([0.1], [0.2], (math.nan, 0, 0, 0, 0, 0), "OPENCV"), "must be finite"),
    ],
)
def test_bad_inputs_are_clear_value_errors(args: tuple, message: str) -> None:
    x, y, coeffs, model = args
    for fn in (distort, undistort):
        with pytest.raises(ValueError, match=message):
            fn(torch.tensor(x, dtype=torch.float64), torch.tensor(y, dtype=torch.float64), coeffs, model)


def test_the_coefficient_order_is_nerfstudios() -> None:
    assert DISTORTION_KEYS == ("k1", "k2", "k3", "k4", "p1", "p2")
    assert CAMERA_MODELS == ("PINHOLE", "SIMPLE_PINHOLE", "OPENCV", "OPENCV_FISHEYE")
