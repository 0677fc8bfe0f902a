"""Density activations: a ReLU that cannot stay dead.

Why: early in a FourieRF run the band holds little more than the density's mean, so the whole field is nearly one
number. Under TensoRF's ReLU (the real-scene preset) one Adam step can take that number below zero everywhere; then
no sample passes a gradient, Adam's momentum carries the factors further down, and the field renders nothing until
the band opens far enough to vary it (docs/defaults.md#a-relu-density-that-cannot-stay-dead).
``RevivingReLU`` is the ReLU forward and backward except on a training batch with no positive density in a field
that is dead: one that had lit an earlier batch, or that has been dark for ``patience`` batches since its start.
There the gradient passes as if through the identity, which tells the factors which way the loss wants the density
to go. The two cases differ because a freshly initialised field is often dark for a few batches and comes back by
itself, while a field that went dark after rendering something stays dark until the band opens, and the sooner it is
revived the better it ends. A constant leak would not do: Adam normalises away its scale, so the leaked gradient of
the empty space pulls on every factor of a live field as hard as the real one.
"""

from __future__ import annotations

import torch
from torch import Tensor, nn


class _RevivingReLU(torch.autograd.Function):
    @staticmethod
    def forward(  # type: ignore[override]
        ctx, x: Tensor, dark_batches: Tensor, lit: Tensor, revived: Tensor, patience: int
    ) -> Tensor:
        y = torch.relu(x)
        dark = y.amax() <= 0  # decided on the device: no host wait (the GPU paths count them)
        dark_batches.copy_(torch.where(dark, dark_batches + 1, 0))  # batches in a row without a positive density
        revive = dark & (lit | (dark_batches >= patience))
        lit.logical_or_(~dark)
        revived.add_(revive.long())
        ctx.save_for_backward(y, revive)
        return y

    @staticmethod
    def backward(ctx, grad: Tensor) -> tuple[Tensor, None, None, None, None]:  # type: ignore[override]
        y, revive = ctx.saved_tensors
        relu_grad = torch.ops.aten.threshold_backward(grad, y, 0.0)  # what torch.relu's own backward computes
        return torch.where(revive, grad, relu_grad), None, None, None, None


class RevivingReLU(nn.Module):
    """ReLU whose gradient passes everywhere on a training batch with no positive density once the field is dead:
    ``lit`` (an earlier batch had a positive density) or ``dark_batches`` in a row reached ``patience`` (1: every dark
    batch). Both are buffers, kept in checkpoints, as is ``revived``, the count of batches it revived: whether revival
    acted at all in a run is otherwise invisible (a run it never acted on is TensoRF's ReLU to the bit). Plain ReLU
    wherever no gradient is taken."""

    def __init__(self, patience: int) -> None:
        super().__init__()
        if patience < 1:
            raise ValueError(f"patience must be at least 1 training batch, got {patience}")
        self.patience = patience
        self.register_buffer("dark_batches", torch.zeros((), dtype=torch.long))
        self.register_buffer("lit", torch.zeros((), dtype=torch.bool))
        self.register_buffer("revived", torch.zeros((), dtype=torch.long))

    def forward(self, x: Tensor) -> Tensor:
        if not torch.is_grad_enabled() or not x.requires_grad or x.numel() == 0:
            return torch.relu(x)  # renders and the occupancy grid; amax of an empty batch would raise
        return _RevivingReLU.apply(x, self.dark_batches, self.lit, self.revived, self.patience)

    def _load_from_state_dict(self, state_dict, prefix, *args) -> None:  # type: ignore[override]
        # checkpoints written before these existed: no dark batch counted, and a run that was saved had been lit
        state_dict.setdefault(prefix + "dark_batches", torch.zeros((), dtype=torch.long))
        state_dict.setdefault(prefix + "lit", torch.ones((), dtype=torch.bool))
        state_dict.setdefault(prefix + "revived", torch.zeros((), dtype=torch.long))  # not counted then
        super()._load_from_state_dict(state_dict, prefix, *args)

    def extra_repr(self) -> str:
        return f"patience={self.patience}"
