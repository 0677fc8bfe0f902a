"""Losses: photometric MSE and the grid regularisers (TV on planes/lines, density L1, TensoRF's normalisations);
the few-shot ray regularisers are in ``model_components.regularisers``.

The TV terms take the sum of squared differences as an argument: the reference below is plain autograd;
``fourierf_plugin.accel.tv`` gives the same values with a cheaper backward.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence

import torch
from torch import Tensor

SquaredDifferences = Callable[[Tensor, tuple[int, ...], tuple[float, ...]], Tensor]
"""``(x, dims, scales) -> Σ_k scales[k] Σ (Δ_{dims[k]} x)²``, a 0-d tensor."""


def mse(pred: Tensor, target: Tensor) -> Tensor:
    """Mean squared error; 0 (not NaN) for an empty batch."""
    if pred.numel() == 0:
        return (pred - target).sum()
    return torch.mean((pred - target) ** 2)


def squared_differences(x: Tensor, dims: tuple[int, ...], scales: tuple[float, ...]) -> Tensor:
    """``Σ_k scale_k Σ (Δ_k x)²`` over the given dims (the reference ``SquaredDifferences``)."""
    return sum((scale * x.diff(dim=d).square().sum() for d, scale in zip(dims, scales, strict=True)), x.new_zeros(()))


def _total_variation(x: Tensor, dims: tuple[int, ...], sq: SquaredDifferences) -> Tensor:
    """``Σ_d 2 Σ(Δ_d x)² / (number of differences along d)`` over the dims longer than 1 (0 when there are none)."""
    dims = tuple(d for d in dims if x.shape[d] > 1)
    if not dims:
        return x.new_zeros(())
    scales = tuple(2.0 * x.shape[d] / (x.numel() * (x.shape[d] - 1)) for d in dims)
    return sq(x, dims, scales)


def total_variation_2d(plane: Tensor, sq: SquaredDifferences = squared_differences) -> Tensor:
    """TensoRF's TV of a [C, H, W] plane: 2 (Σ(Δ_h)²/(C(H-1)W) + Σ(Δ_w)²/(CH(W-1))); 0 along 1-wide axes."""
    return _total_variation(plane, (1, 2), sq)


def total_variation_1d(line: Tensor, sq: SquaredDifferences = squared_differences) -> Tensor:
    """TV of a [C, L] line, normalised like the planes: 2 Σ(Δ)² / (C(L-1))."""
    return _total_variation(line, (1,), sq)


def grid_tv(
    planes: Sequence[Tensor],
    lines: Sequence[Tensor],
    plane_scale: float = 1e-2,
    line_scale: float = 1e-3,
    sq: SquaredDifferences = squared_differences,
) -> Tensor:
    """``Σ_i 1e-2 TV(P_i)`` for VM (planes only); CP grids have no planes and use ``Σ_i 1e-3 TV(L_i)``."""
    if planes:
        return sum((total_variation_2d(p, sq) for p in planes), start=planes[0].new_zeros(())) * plane_scale
    return sum((total_variation_1d(line, sq) for line in lines), start=lines[0].new_zeros(())) * line_scale


def density_l1(planes: Sequence[Tensor], lines: Sequence[Tensor]) -> Tensor:
    """TensoRF's density sparsity term ``Σ_i mean|P_i| + mean|L_i|``."""
    terms = [p.abs().mean() for p in planes] + [line.abs().mean() for line in lines]
    return torch.stack(terms).sum()
