"""The total variation's sum of squared differences with a hand-written backward (``accel.tv``) is the reference's.

``losses.squared_differences`` is plain autograd; ``accel.tv.squared_differences`` sums in float64 and writes its
own backward. Here both give the same values and gradients on planes and lines of every awkward shape (1-wide axes
included), alone and inside ``total_variation_2d/1d`` and ``grid_tv``, and the hand-written backward passes
gradcheck.
"""

from __future__ import annotations

import pytest
import torch

from fourierf_plugin.accel import tv
from fourierf_plugin.model_components import losses

SHAPES = [(2, 4, 5), (1, 1, 6), (3, 6, 1), (2, 7, 7), (1, 1, 1)]


def _value_and_gradient(sq: losses.SquaredDifferences, x: torch.Tensor, *args) -> tuple[torch.Tensor, torch.Tensor]:
    x = x.detach().clone().requires_grad_()
    value = sq(x, *args)
    (grad,) = torch.autograd.grad(value, x, torch.tensor(0.7, dtype=x.dtype))
    return value.detach(), grad


@pytest.mark.parametrize("shape", SHAPES)
@pytest.mark.parametrize("dtype", [torch.float64, torch.float32])
def test_squared_differences_equal_the_reference_in_values_and_gradients(
    shape: tuple[int, int, int], dtype: torch.dtype
) -> None:
    x = torch.randn(shape, generator=torch.Generator().manual_seed(sum(shape)), dtype=dtype)
    tol = {"atol": 1e-12, "rtol": 1e-12} if dtype == torch.float64 else {"atol": 1e-5, "rtol": 1e-5}
    for dims, scales in [((1, 2), (0.3, 1.7)), ((1,), (2.0,)), ((2,), (0.5,)), ((0, 1, 2), (1.0, 2.0, 3.0))]:
        ours = _value_and_gradient(tv.squared_differences, x, dims, scales)
        ref = _value_and_gradient(losses.squared_differences, x, dims, scales)
        assert ours[0].dtype == dtype and ours[0].shape == ()
        for a, b in zip(ours, ref, strict=True):
            torch.testing.assert_close(a, b, **tol, msg=f"dims={dims}")


@pytest.mark.parametrize("shape", SHAPES)
def test_total_variation_terms_equal_the_reference(shape: tuple[int, int, int]) -> None:
    gen = torch.Generator().manual_seed(7)
    planes = [torch.randn(shape, generator=gen, dtype=torch.float64) for _ in range(3)]
    lines = [torch.randn(shape[0], shape[2], generator=gen, dtype=torch.float64) for _ in range(3)]
    cases = [
        (lambda ps, ls, sq: losses.total_variation_2d(ps[0], sq), True),
        (lambda ps, ls, sq: losses.total_variation_1d(ls[0], sq), False),
        (lambda ps, ls, sq: losses.grid_tv(ps, ls, sq=sq), True),  # VM: planes
        (lambda ps, ls, sq: losses.grid_tv([], ls, sq=sq), False),  # CP: lines
    ]
    for term, on_planes in cases:
        results = []
        for sq in (tv.squared_differences, losses.squared_differences):
            ps = [p.clone().requires_grad_() for p in planes]
            ls = [line.clone().requires_grad_() for line in lines]
            value = term(ps, ls, sq)
            params = ps if on_planes else ls
            grads = torch.autograd.grad(value, params, allow_unused=True) if value.requires_grad else None
            results.append((value.detach(), grads))
        (ours, ours_grads), (ref, ref_grads) = results
        torch.testing.assert_close(ours, ref, atol=1e-12, rtol=1e-12)
        assert (ours_grads is None) == (ref_grads is None)  # no differences at all: a constant 0 either way
        for a, b in zip(ours_grads or (), ref_grads or (), strict=True):
            torch.testing.assert_close(a, b, atol=1e-12, rtol=0)


@pytest.mark.parametrize("shape", [(2, 4, 5), (1, 1, 6), (3, 6, 1), (2, 7, 7)])
def test_hand_written_backward_passes_gradcheck(shape: tuple[int, int, int]) -> None:
    plane = torch.randn(shape, dtype=torch.float64, requires_grad=True)
    dims = tuple(d for d in (1, 2) if shape[d] > 1)
    assert torch.autograd.gradcheck(lambda x: tv.squared_differences(x, dims, (0.3, 1.7)[: len(dims)]), (plane,))
    assert torch.autograd.gradcheck(lambda x: losses.total_variation_2d(x, tv.squared_differences), (plane,))
    line = torch.randn(shape[0], shape[2], dtype=torch.float64, requires_grad=True)
    if shape[2] > 1:
        assert torch.autograd.gradcheck(lambda x: losses.total_variation_1d(x, tv.squared_differences), (line,))
