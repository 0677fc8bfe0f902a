"""Losses: photometric MSE and the grid regularisers (TV on planes/lines, density L1), TensoRF's normalisations."""

from __future__ import annotations

from collections.abc import Sequence

import torch
from torch import Tensor


def mse(pred: Tensor, target: Tensor) -> Tensor:
    return torch.mean((pred - target) ** 2)


def total_variation_2d(plane: Tensor) -> Tensor:
    """TensoRF's TV of a [C, H, W] plane: 2 (Σ(Δ_h)²/(C(H-1)W) + Σ(Δ_w)²/(CH(W-1))); 0 along 1-wide axes."""
    c, h, w = plane.shape
    tv = plane.new_zeros(())
    if h > 1:
        tv = tv + ((plane[:, 1:, :] - plane[:, :-1, :]) ** 2).sum() / (c * (h - 1) * w)
    if w > 1:
        tv = tv + ((plane[:, :, 1:] - plane[:, :, :-1]) ** 2).sum() / (c * h * (w - 1))
    return 2.0 * tv


def total_variation_1d(line: Tensor) -> Tensor:
    """TV of a [C, L] line, normalised like the planes: 2 Σ(Δ)² / (C(L-1))."""
    c, length = line.shape
    if length < 2:
        return line.new_zeros(())
    return 2.0 * ((line[:, 1:] - line[:, :-1]) ** 2).sum() / (c * (length - 1))


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
