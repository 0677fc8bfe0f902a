"""Losses: photometric MSE and the grid regularisers (TV on planes/lines, density L1), TensoRF's normalisations."""

from __future__ import annotations

from collections.abc import Sequence

import torch
from torch import Tensor


def mse(pred: Tensor, target: Tensor) -> Tensor:
    """Mean squared error; 0 (not NaN) for an empty batch."""
    if pred.numel() == 0:
        return (pred - target).sum()
    return torch.mean((pred - target) ** 2)


class _SquaredDifferences(torch.autograd.Function):
    """``Σ_k scale_k Σ (Δ_k x)²`` over the given dims, with a hand-written backward.

    Autograd would turn each slice and difference into full-size zero-filled copies; TV runs on every grid value at
    every iteration, so this halves its cost. Gradient: ``2 scale Δx`` added at the upper and removed at the lower
    neighbour.
    """

    @staticmethod
    def forward(ctx, x: Tensor, dims: tuple[int, ...], scales: tuple[float, ...]) -> Tensor:  # type: ignore[override]
        diffs = [x.diff(dim=d) for d in dims]
        ctx.save_for_backward(*diffs)
        ctx.dims, ctx.scales, ctx.shape = dims, scales, x.shape
        total = x.new_zeros((), dtype=torch.float64)
        for diff, scale in zip(diffs, scales, strict=True):
            flat = diff.reshape(-1)
            total = total + scale * torch.dot(flat, flat).double()
        return total.to(x.dtype)

    @staticmethod
    def backward(ctx, grad: Tensor) -> tuple[Tensor, None, None]:  # type: ignore[override]
        out = grad.new_zeros(ctx.shape)
        for diff, d, scale in zip(ctx.saved_tensors, ctx.dims, ctx.scales, strict=True):
            step = diff * (2.0 * scale * grad)
            n = ctx.shape[d]
            out.narrow(d, 1, n - 1).add_(step)
            out.narrow(d, 0, n - 1).sub_(step)
        return out, None, None


def _total_variation(x: Tensor, dims: tuple[int, ...]) -> Tensor:
    """``Σ_d 2 Σ(Δ_d x)² / (number of differences along d)`` over the dims longer than 1 (0 when there are none)."""
    dims = tuple(d for d in dims if x.shape[d] > 1)
    if not dims:
        return x.new_zeros(())
    scales = tuple(2.0 * x.shape[d] / (x.numel() * (x.shape[d] - 1)) for d in dims)
    return _SquaredDifferences.apply(x, dims, scales)


def total_variation_2d(plane: Tensor) -> Tensor:
    """TensoRF's TV of a [C, H, W] plane: 2 (Σ(Δ_h)²/(C(H-1)W) + Σ(Δ_w)²/(CH(W-1))); 0 along 1-wide axes."""
    return _total_variation(plane, (1, 2))


def total_variation_1d(line: Tensor) -> Tensor:
    """TV of a [C, L] line, normalised like the planes: 2 Σ(Δ)² / (C(L-1))."""
    return _total_variation(line, (1,))


def grid_tv(
    planes: Sequence[Tensor], lines: Sequence[Tensor], plane_scale: float = 1e-2, line_scale: float = 1e-3
) -> Tensor:
    """``Σ_i 1e-2 TV(P_i)`` for VM (planes only); CP grids have no planes and use ``Σ_i 1e-3 TV(L_i)``."""
    if planes:
        return sum((total_variation_2d(p) for p in planes), start=planes[0].new_zeros(())) * plane_scale
    return sum((total_variation_1d(line) for line in lines), start=lines[0].new_zeros(())) * line_scale


def density_l1(planes: Sequence[Tensor], lines: Sequence[Tensor]) -> Tensor:
    """TensoRF's density sparsity term ``Σ_i mean|P_i| + mean|L_i|``."""
    terms = [p.abs().mean() for p in planes] + [line.abs().mean() for line in lines]
    return torch.stack(terms).sum()
