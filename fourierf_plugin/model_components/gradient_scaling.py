"""'Floaters No More' gradient scaling: identity forward, gradients scaled by clamp(t², 0, 1) backward.

Samples close to the camera get small gradients, so the few views cannot explain their pixels with near floaters.
"""

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


def floaters_scale(t: Tensor) -> Tensor:
    """The Floaters-No-More factor clamp(t², 0, 1) for ray parameters ``t``."""
    return (t * t).clamp(0.0, 1.0)
