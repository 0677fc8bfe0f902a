"""Coarse-to-fine sampling along rays, as pure functions: stratified interval edges for a first level, and a second
level's edges drawn from the first level's weights (mip-NeRF's sampler, which FreeNeRF's LLFF code uses)."""

from __future__ import annotations

import torch
from torch import Tensor

from fourierf_plugin.model_components.rendering import random_on

_EPS = 1e-6


def stratified_edges(
    near: float, far: float, num_rays: int, num_edges: int, generator: torch.Generator | None, device: torch.device
) -> Tensor:
    """Interval edges [R, E] from ``near`` to ``far``: evenly spaced (renders), or each drawn uniformly between the
    midpoints around its even position (training, from ``generator``), so the edges stay sorted."""
    even = torch.linspace(near, far, num_edges, device=device).expand(num_rays, num_edges)
    if generator is None:
        return even.contiguous()
    mids = 0.5 * (even[:, 1:] + even[:, :-1])
    lower = torch.cat([even[:, :1], mids], dim=-1)
    upper = torch.cat([mids, even[:, -1:]], dim=-1)
    return lower + (upper - lower) * random_on(generator, (num_rays, num_edges)).to(device)


def blurred_weights(weights: Tensor, padding: float) -> Tensor:
    """The histogram a second level is drawn from: each interval's weight widened to its neighbours' (a two-tap max,
    then a two-tap mean) plus ``padding``, so no interval near a surface, nor any interval at all, is left out."""
    padded = torch.cat([weights[:, :1], weights, weights[:, -1:]], dim=-1)
    peaks = torch.maximum(padded[:, :-1], padded[:, 1:])
    return 0.5 * (peaks[:, :-1] + peaks[:, 1:]) + padding


def sample_histogram(edges: Tensor, weights: Tensor, num_samples: int, generator: torch.Generator | None) -> Tensor:
    """Sorted ray parameters [R, S] drawn from the piecewise-constant density with ``weights`` [R, E-1] on the intervals
    between ``edges`` [R, E]: the inverse CDF at one uniform draw in each of S equal strata of [0, 1) (training), or at
    S evenly spaced points from 0 to just below 1 (renders)."""
    num_rays, device = edges.shape[0], edges.device
    pdf = weights / weights.sum(dim=-1, keepdim=True).clamp(min=_EPS)
    inner = torch.cumsum(pdf[:, :-1], dim=-1).clamp(max=1.0)
    cdf = torch.cat([torch.zeros_like(pdf[:, :1]), inner, torch.ones_like(pdf[:, :1])], dim=-1)
    if generator is None:
        u = torch.linspace(0.0, 1.0 - _EPS, num_samples, device=device).expand(num_rays, num_samples).contiguous()
    else:
        strata = torch.arange(num_samples, device=device, dtype=edges.dtype)
        u = ((strata + random_on(generator, (num_rays, num_samples)).to(device)) / num_samples).clamp(max=1.0 - _EPS)
    above = torch.searchsorted(cdf.contiguous(), u, right=True).clamp(1, edges.shape[1] - 1)
    below = above - 1
    cdf_below, cdf_above = cdf.gather(1, below), cdf.gather(1, above)
    t_below, t_above = edges.gather(1, below), edges.gather(1, above)
    span = cdf_above - cdf_below
    share = torch.where(span > 0, (u - cdf_below) / span.clamp(min=1e-12), torch.zeros_like(u))
    return t_below + share.clamp(0.0, 1.0) * (t_above - t_below)


def midpoints_and_lengths(edges: Tensor) -> tuple[Tensor, Tensor]:
    """Each interval's midpoint and length, [R, E-1] each: where a level's samples sit and the δ they composite with."""
    return 0.5 * (edges[:, 1:] + edges[:, :-1]), edges[:, 1:] - edges[:, :-1]
