"""ZeroRF's decoder: density and colour from one shared feature through one shared hidden layer.

Followed (eliphatfs/zerorf, ``lib/models/zerorf/decoders.py``, ``CommonDecoder`` with ``sh_coef_only`` off):
``h = W_b f + b_b``; ``σ = trunc_exp(w_σ · SiLU(h) + b_σ)``; ``rgb = sigmoid(W_c SiLU(h + W_d SH₂(d)) + b_c)``,
widened by 0.001 on both sides so 0 and 1 are reachable; Xavier-uniform weights, zero biases, and the direction
layer zeroed, so colour starts view-independent. Unlike TensoRF's density (a sum of components), ZeroRF's density is
this MLP's output. The direction term exists only when the scene's effects ask for view-dependent colour
(zerorf-vm's preset does, as ZeroRF).
"""

from __future__ import annotations

import torch
import torch.nn.functional as F
from torch import Tensor, nn

from fourierf_plugin.field_components.decoder import spherical_harmonics_deg2

SIGMOID_SATURATION = 1e-3
MAX_LOG_DENSITY = 30.0
"""The forward exponent is capped here (σ ≤ 1e13, finite in float32 after any step length); ZeroRF has no cap."""
GRAD_CLAMP = 15.0


class TruncExp(torch.autograd.Function):
    """``exp(x)`` whose gradient is computed at ``x`` clamped to ±15 (torch-ngp's ``trunc_exp``, as ZeroRF uses): a
    large pre-activation cannot produce an exploding gradient."""

    @staticmethod
    def forward(ctx, x: Tensor) -> Tensor:  # type: ignore[override]
        ctx.save_for_backward(x)
        return torch.exp(x.clamp(max=MAX_LOG_DENSITY))

    @staticmethod
    def backward(ctx, grad: Tensor) -> Tensor:  # type: ignore[override]
        (x,) = ctx.saved_tensors
        return grad * torch.exp(x.clamp(-GRAD_CLAMP, GRAD_CLAMP))


def trunc_exp(x: Tensor) -> Tensor:
    return TruncExp.apply(x)


class ZeroRFDecoder(nn.Module):
    def __init__(self, in_dim: int, width: int, view_dependent: bool, generator: torch.Generator) -> None:
        super().__init__()
        self.base = nn.Linear(in_dim, width)
        self.density_head = nn.Linear(width, 1)
        self.view_layer = nn.Linear(9, width) if view_dependent else None
        self.color_head = nn.Linear(width, 3)
        for layer in (self.base, self.density_head, self.color_head):
            nn.init.xavier_uniform_(layer.weight, generator=generator)
            nn.init.zeros_(layer.bias)
        if self.view_layer is not None:
            nn.init.zeros_(self.view_layer.weight)
            nn.init.zeros_(self.view_layer.bias)

    @property
    def view_dependent(self) -> bool:
        return self.view_layer is not None

    def hidden(self, features: Tensor) -> Tensor:
        """The shared layer ``W_b f + b_b`` [N, width] both heads read."""
        return self.base(features)

    def density(self, hidden: Tensor) -> Tensor:
        """σ ≥ 0 [N] from the shared layer."""
        return trunc_exp(self.density_head(F.silu(hidden)).squeeze(-1))

    def rgb(self, hidden: Tensor, directions: Tensor | None) -> Tensor:
        """Colour [N, 3] in [-0.001, 1.001] from the shared layer (and unit directions when view-dependent)."""
        if self.view_layer is not None:
            if directions is None:
                raise ValueError("a view-dependent decoder needs ray directions")
            hidden = hidden + self.view_layer(spherical_harmonics_deg2(directions))
        rgb = torch.sigmoid(self.color_head(F.silu(hidden)))
        return rgb * (1.0 + 2.0 * SIGMOID_SATURATION) - SIGMOID_SATURATION
