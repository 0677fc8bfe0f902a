"""Gradient scaling: identity forward, gradients multiplied by a given factor backward (Floaters-No-More's
``regularisers.floaters`` gives the factor)."""

from __future__ import annotations

import torch
from torch import Tensor


class _ScaleGradient(torch.autograd.Function):
    @staticmethod
    def forward(ctx, value: Tensor, scale: Tensor) -> Tensor:  # type: ignore[override]
        ctx.save_for_backward(scale)
        return value.view_as(value)

    @staticmethod
    def backward(ctx, grad: Tensor) -> tuple[Tensor, None]:  # type: ignore[override]
        (scale,) = ctx.saved_tensors
        return grad * scale, None


def scale_gradient(value: Tensor, scale: Tensor) -> Tensor:
    """``value`` unchanged, its gradient multiplied by ``scale`` (broadcast to value's shape)."""
    return _ScaleGradient.apply(value, scale.detach().expand_as(value))
