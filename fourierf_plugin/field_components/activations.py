"""Density activations: a ReLU that cannot stay dead.

Why: early in a FourieRF run the band holds little more than the density's mean, so the whole field is nearly one
number. Under TensoRF's ReLU (the real-scene preset) one Adam step can take that number below zero everywhere; then
no sample passes a gradient, Adam's momentum carries the factors further down, and the field renders nothing until
the band opens far enough to vary it (README, "A ReLU density that cannot stay dead"). ``reviving_relu`` is the ReLU
forward and backward whenever any of the batch's densities is positive, so a live run is unchanged to the last bit;
only when every one is zero does the gradient pass as if through the identity, which tells the factors which way the
loss wants the density to go. A constant leak would not do: Adam normalises away its scale, so the leaked gradient of
the empty space pulls on every factor of a live field as hard as the real one (tried: fern val −2.9 dB).
"""

from __future__ import annotations

import torch
from torch import Tensor


class _RevivingReLU(torch.autograd.Function):
    @staticmethod
    def forward(ctx, x: Tensor) -> Tensor:  # type: ignore[override]
        y = torch.relu(x)
        dead = y.amax() <= 0  # decided on the device: no host wait (the GPU paths count them)
        ctx.save_for_backward(y, dead)
        return y

    @staticmethod
    def backward(ctx, grad: Tensor) -> Tensor:  # type: ignore[override]
        y, dead = ctx.saved_tensors
        relu_grad = torch.ops.aten.threshold_backward(grad, y, 0.0)  # what torch.relu's own backward computes
        return torch.where(dead, grad, relu_grad)


def reviving_relu(x: Tensor) -> Tensor:
    """ReLU whose gradient passes everywhere while all of ``x`` is at or below zero (a dead field), else plain."""
    if not torch.is_grad_enabled() or not x.requires_grad or x.numel() == 0:
        return torch.relu(x)
    return _RevivingReLU.apply(x)
