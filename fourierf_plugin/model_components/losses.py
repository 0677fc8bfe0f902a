"""Losses: photometric MSE, the grid regularisers (TV on planes/lines, density L1, TensoRF's normalisations) and
the ray regularisers (depth smoothness, distortion, entropy).

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


def depth_smoothness(depth: Tensor) -> Tensor:
    """RegNeRF's depth smoothness of patches [P, S, S]: the mean squared difference between vertical neighbours plus
    that between horizontal ones (0 for a constant patch, and 0, not NaN, for no patches)."""
    if depth.shape[0] == 0:
        return depth.sum()
    return depth.diff(dim=1).square().mean() + depth.diff(dim=2).square().mean()


def distortion(weights: Tensor, s: Tensor) -> Tensor:
    """mip-NeRF 360's distortion loss, mean over rays: ``Σ_ij w_i w_j |m_i - m_j| + Σ_i w_i² d_i / 3``.

    Why: few-shot fields spread each ray's weight over several depths (floaters, doubled geometry); this term is
    smallest when the weight sits in one short interval. ``s`` [R, N] are ascending sample positions in normalised
    ray distance (0 at the near end, 1 at the far end); sample i stands for the interval [s_i, s_{i+1}] (the last
    for none, as its compositing interval is 0), m its midpoint, d its length. The pairwise sum is taken in O(N)
    from exclusive prefix sums of w and w m. 0, not NaN, for no rays.
    """
    if weights.shape[0] == 0:
        return weights.sum()
    lengths = torch.cat([s.diff(dim=-1), torch.zeros_like(s[..., :1])], dim=-1)
    mids = s + 0.5 * lengths
    wm = weights * mids
    w_before = torch.cumsum(weights, dim=-1) - weights
    wm_before = torch.cumsum(wm, dim=-1) - wm
    pairwise = 2.0 * (wm * w_before - weights * wm_before).sum(dim=-1)
    own = (weights.square() * lengths).sum(dim=-1) / 3.0
    return (pairwise + own).mean()


def ray_entropy(alpha: Tensor, accumulation: Tensor, threshold: float) -> Tensor:
    """InfoNeRF's ray entropy in bits, summed over the rays whose accumulation exceeds ``threshold`` and divided by
    all rays: ``-Σ_i p_i log2 p_i`` with ``p_i = α_i / Σ_j α_j`` the ray's opacity, normalised.

    Why: a few-shot field explains each view with density spread along the ray (fog, floaters); the entropy is 0
    when a ray's opacity sits in one sample and log2 N when it is even over N. Rays that hit nothing are left out, so
    empty space is not pushed to gather an opaque sample. Only those rays enter the logarithm: a masked-out ray has
    no gradient, not a NaN. 0 for no rays.
    """
    if alpha.shape[0] == 0:
        return alpha.sum()
    hit = alpha[accumulation > threshold]
    p = hit / hit.sum(dim=-1, keepdim=True).clamp(min=1e-10)
    entropy = -(p * torch.log2(p + 1e-10)).sum()
    return entropy / alpha.shape[0]
