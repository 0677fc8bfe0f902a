"""``RevivingReLU``: TensoRF's ReLU while any density of the batch is positive, a pass-through gradient on a batch with
none in a dead field (lit before, or dark for ``patience`` batches since its start), and the plain ReLU wherever no
gradient is taken. With patience 1 every dark batch revives."""

from __future__ import annotations

import pytest
import torch

from fourierf_plugin.field_components.activations import RevivingReLU


def reviving_relu(x: torch.Tensor) -> torch.Tensor:
    """A fresh activation reviving at the first dark batch: one call is one batch."""
    return RevivingReLU(patience=1)(x)


def _grad(fn, x: torch.Tensor, upstream: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    x = x.clone().requires_grad_()
    y = fn(x)
    y.backward(upstream)
    return y.detach(), x.grad


def test_live_batch_is_relu_to_the_last_bit() -> None:
    x = torch.randn(1000, generator=torch.Generator().manual_seed(0), dtype=torch.float64)
    up = torch.randn(1000, generator=torch.Generator().manual_seed(1), dtype=torch.float64)
    y, g = _grad(reviving_relu, x, up)
    y_ref, g_ref = _grad(torch.relu, x, up)
    assert torch.equal(y, y_ref) and torch.equal(g, g_ref)
    assert (g[x <= 0] == 0).all() and (g[x > 0] == up[x > 0]).all()


def test_one_positive_density_keeps_the_batch_plain() -> None:
    x = torch.tensor([-3.0, -1.0, 0.0, 1e-6])
    up = torch.tensor([1.0, 2.0, 3.0, 4.0])
    y, g = _grad(reviving_relu, x, up)
    assert torch.equal(y, torch.tensor([0.0, 0.0, 0.0, 1e-6]))
    assert torch.equal(g, torch.tensor([0.0, 0.0, 0.0, 4.0]))


def test_dead_batch_passes_the_gradient_but_renders_zero() -> None:
    x = torch.tensor([[-3.0, -1.0], [0.0, -1e-6]])
    up = torch.tensor([[1.0, -2.0], [3.0, 4.0]])
    y, g = _grad(reviving_relu, x, up)
    assert torch.equal(y, torch.zeros(2, 2))  # the forward stays the ReLU: nothing renders
    assert torch.equal(g, up)  # every sample tells the factors which way the loss wants the density


def test_without_gradients_it_is_relu() -> None:
    x = torch.tensor([-1.0, 2.0])
    with torch.no_grad():
        assert torch.equal(reviving_relu(x), torch.relu(x))
    assert torch.equal(reviving_relu(x), torch.relu(x))  # a leaf without requires_grad


def test_gradients_stay_finite_on_extreme_inputs() -> None:
    for x in (torch.full((5,), -1e30), torch.tensor([-float("inf"), -1.0]), torch.tensor([1e30, -1e30])):
        y, g = _grad(reviving_relu, x, torch.ones_like(x))
        assert torch.isfinite(g).all() and (y >= 0).all()


def test_an_empty_batch_is_relu() -> None:
    x = torch.zeros(0, requires_grad=True)
    y = reviving_relu(x)
    y.sum().backward()
    assert y.shape == (0,) and x.grad.shape == (0,)


def _passes(relu: RevivingReLU, batches: list[torch.Tensor]) -> list[bool]:
    """Per batch, whether the gradient of its first (negative) sample passed: only while reviving."""
    return [bool((_grad(relu, x, torch.ones(2))[1][0] != 0).item()) for x in batches]


DARK, LIT = torch.tensor([-1.0, -2.0]), torch.tensor([-1.0, 0.5])


def test_a_field_dark_from_its_start_waits_patience_batches() -> None:
    relu = RevivingReLU(patience=3)
    assert _passes(relu, [DARK, DARK, DARK, DARK]) == [False, False, True, True]


def test_a_field_that_went_dark_after_lighting_revives_at_once() -> None:
    relu = RevivingReLU(patience=3)
    # dark from the start for two batches (it comes back by itself), then lit, then dead: revived at once
    assert _passes(relu, [DARK, DARK, LIT, DARK, DARK, LIT]) == [False, False, False, True, True, False]
    assert relu.lit.item() and relu.dark_batches.item() == 0
    assert relu.revived.item() == 2  # the count says revival acted, and on how many batches


def test_a_field_that_never_went_dark_counts_no_revival() -> None:
    relu = RevivingReLU(patience=1)
    assert _passes(relu, [LIT, LIT]) == [False, False]
    with torch.no_grad():
        relu(DARK)  # a render: nothing revived
    assert relu.revived.item() == 0


def test_patience_one_revives_every_dark_batch() -> None:
    assert _passes(RevivingReLU(patience=1), [DARK, LIT, DARK]) == [True, False, True]


def test_checkpoints_from_before_the_buffers_load_as_lit() -> None:
    relu = RevivingReLU(patience=3)
    relu.load_state_dict({})
    assert relu.lit.item() and relu.dark_batches.item() == 0 and relu.revived.item() == 0
    assert _passes(relu, [DARK]) == [True]


def test_renders_do_not_count_dark_batches() -> None:
    relu = RevivingReLU(patience=1)
    with torch.no_grad():
        relu(torch.tensor([-1.0, -2.0]))
    assert relu.dark_batches.item() == 0


def test_patience_below_one_is_refused() -> None:
    with pytest.raises(ValueError, match="at least 1"):
        RevivingReLU(patience=0)
