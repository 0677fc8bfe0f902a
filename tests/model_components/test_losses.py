"""The reference photometric and grid losses, with TensoRF's normalisations (spec 3.6).

Closed forms on ramps and constants, the spec's formula on random planes, 1-wide axes and empty batches. The TV's
faster sum of squared differences (``accel.tv``) is compared with these in ``tests/accel/test_tv.py``.
"""

from __future__ import annotations

import pytest
import torch

from fourierf_plugin.model_components.losses import (
    density_l1,
    grid_tv,
    mse,
    total_variation_1d,
    total_variation_2d,
)


def _ramp_plane(c: int, h: int, w: int, a: float, b: float) -> torch.Tensor:
    rows = torch.arange(h, dtype=torch.float64)[:, None]
    cols = torch.arange(w, dtype=torch.float64)[None, :]
    return (a * rows + b * cols).expand(c, h, w).clone()


def test_mse() -> None:
    pred = torch.tensor([[0.0, 1.0], [2.0, 3.0]])
    assert float(mse(pred, torch.zeros(2, 2))) == pytest.approx(3.5)
    assert float(mse(pred, pred)) == 0.0


def test_tv_constant_plane_is_zero() -> None:
    assert float(total_variation_2d(torch.full((3, 6, 9), 0.7))) == 0.0


@pytest.mark.parametrize(("h", "w", "a", "b"), [(5, 7, 0.3, -0.2), (8, 3, 1.0, 0.0), (4, 4, 0.0, 2.5)])
def test_tv_linear_ramp_closed_form(h: int, w: int, a: float, b: float) -> None:
    """Δ_h ≡ a and Δ_w ≡ b, and each sum is divided by its own count: TV = 2 (a² + b²), whatever C, H, W."""
    tv = total_variation_2d(_ramp_plane(3, h, w, a, b))
    assert float(tv) == pytest.approx(2.0 * (a * a + b * b), rel=1e-12, abs=1e-15)


def test_tv_matches_spec_formula_on_random_plane() -> None:
    p = torch.randn(4, 6, 5, generator=torch.Generator().manual_seed(0), dtype=torch.float64)
    c, h, w = p.shape
    dh = ((p[:, 1:] - p[:, :-1]) ** 2).sum() / (c * (h - 1) * w)
    dw = ((p[:, :, 1:] - p[:, :, :-1]) ** 2).sum() / (c * h * (w - 1))
    assert float(total_variation_2d(p)) == pytest.approx(float(2 * (dh + dw)), rel=1e-12)


def test_tv_one_wide_axes_are_zero_and_finite() -> None:
    ramp_h = _ramp_plane(2, 5, 1, 0.5, 0.0)  # W = 1: only the h term
    assert float(total_variation_2d(ramp_h)) == pytest.approx(2 * 0.25)
    ramp_w = _ramp_plane(2, 1, 5, 0.0, 0.5)  # H = 1: only the w term
    assert float(total_variation_2d(ramp_w)) == pytest.approx(2 * 0.25)
    single = total_variation_2d(torch.randn(3, 1, 1))
    assert torch.isfinite(single) and float(single) == 0.0
    line = total_variation_1d(torch.randn(3, 1))
    assert torch.isfinite(line) and float(line) == 0.0


def test_tv_1d_closed_form() -> None:
    line = (0.4 * torch.arange(9, dtype=torch.float64)).expand(2, 9)
    assert float(total_variation_1d(line)) == pytest.approx(2 * 0.16)
    assert float(total_variation_1d(torch.full((3, 5), -2.0))) == 0.0


def test_tv_gradients_finite() -> None:
    p = torch.randn(2, 4, 1, requires_grad=True)
    line = torch.randn(2, 1, requires_grad=True)
    (total_variation_2d(p) + total_variation_1d(line)).backward()
    assert torch.isfinite(p.grad).all()
    assert line.grad is None or torch.isfinite(line.grad).all()


def test_grid_tv_vm_uses_planes_only() -> None:
    planes = [_ramp_plane(2, 4, 5, 1.0, 0.0), _ramp_plane(2, 3, 3, 0.0, 1.0), torch.zeros(2, 4, 4, dtype=torch.float64)]
    lines = [torch.randn(2, 9, dtype=torch.float64) for _ in range(3)]
    assert float(grid_tv(planes, lines)) == pytest.approx(1e-2 * (2.0 + 2.0))
    assert float(grid_tv(planes, lines, plane_scale=1.0)) == pytest.approx(4.0)


def test_grid_tv_cp_uses_lines() -> None:
    lines = [(s * torch.arange(6, dtype=torch.float64)).expand(3, 6) for s in (1.0, 2.0, 0.0)]
    assert float(grid_tv([], lines)) == pytest.approx(1e-3 * 2 * (1.0 + 4.0))
    assert float(grid_tv([], lines, line_scale=1.0)) == pytest.approx(10.0)


def test_density_l1_value() -> None:
    planes = [torch.full((2, 3, 3), -0.5), torch.ones(1, 2, 2), torch.zeros(4, 2, 5)]
    lines = [torch.tensor([[1.0, -3.0]]), torch.zeros(2, 4), torch.full((1, 3), 0.25)]
    assert float(density_l1(planes, lines)) == pytest.approx(0.5 + 1.0 + 0.0 + 2.0 + 0.0 + 0.25)
    # CP: lines only.
    assert float(density_l1([], lines)) == pytest.approx(2.25)


def test_losses_finite_for_tiny_inputs() -> None:
    planes = [torch.randn(1, 1, 1), torch.randn(1, 1, 2), torch.randn(1, 2, 1)]
    lines = [torch.randn(1, 1), torch.randn(1, 2), torch.randn(1, 1)]
    for value in (grid_tv(planes, lines), grid_tv([], lines), density_l1(planes, lines), density_l1([], lines[:1])):
        assert value.shape == () and torch.isfinite(value)


def test_mse_of_an_empty_batch_is_zero_not_nan() -> None:
    pred = torch.zeros(0, 3, requires_grad=True)
    value = mse(pred, torch.zeros(0, 3))
    assert float(value.detach()) == 0.0
    value.backward()
