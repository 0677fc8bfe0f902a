"""Marching rays through the field: density at the samples in occupied cells, colour at the samples that show.

Samples are addressed by flat indices into the [R·N] samples of a batch: a boolean mask would run a nonzero pass at
every use (indexing, index_put and their backward), about three times the cost of one index_select each.
"""

from __future__ import annotations

import math
from collections.abc import Callable

import torch
from torch import Tensor

from fourierf_plugin.model_components.gradient_scaling import scale_gradient
from fourierf_plugin.model_components.occupancy import OccupancyGrid
from fourierf_plugin.model_components.ray_sampling import RaySamples
from fourierf_plugin.model_components.rendering import accumulate, composite_weights
from fourierf_plugin.utils.phases import phase

DensityFn = Callable[[Tensor], Tensor]
"""World points [M, 3] -> σ [M]."""
ColorFn = Callable[[Tensor, Tensor | None], Tensor]
"""World points [M, 3] and unit view directions [M, 3] (or None) -> colour [M, 3]."""


def occupied(points: Tensor, index: Tensor, occupancy: OccupancyGrid) -> tuple[Tensor, Tensor]:
    """The listed samples (flat ``index`` into ``points`` [M, 3]) that lie in occupied cells: indices and points."""
    selected = points.index_select(0, index)
    if not occupancy.active or not index.numel():
        return index, selected
    with phase("sampling"):
        keep = occupancy.query(selected).nonzero().squeeze(1)
    return index.index_select(0, keep), selected.index_select(0, keep)


def densities(density: DensityFn, samples: RaySamples, occupancy: OccupancyGrid) -> Tensor:
    """σ [R, N]: the field's density at every sample inside the box and in an occupied cell, 0 elsewhere."""
    num_rays, num_samples = samples.shape
    points = samples.points.view(-1, 3)
    index, selected = occupied(points, samples.inside.view(-1).nonzero().squeeze(1), occupancy)
    sigma = points.new_zeros(num_rays * num_samples)
    if index.numel():
        sigma = sigma.index_put((index,), density(selected))
    return sigma.view(num_rays, num_samples)


def densities_that_show(
    density: DensityFn, samples: RaySamples, occupancy: OccupancyGrid, distance_scale: float, weight_threshold: float
) -> Tensor:
    """σ [R, N] with gradients only where it shows: ``densities`` read once without gradients, then again with them at
    the samples whose compositing weight exceeds ``weight_threshold``; every other sample counts as empty.

    ZeroRF's occlusion culling (its renderer's ``occlusion_culling_th``, 1e-4): samples in empty space or behind an
    opaque surface change the image by less than the threshold, and a field with an expensive density (a decoder MLP
    per sample) skips its backward there.
    """
    with torch.no_grad():
        weights = composite_weights(densities(density, samples, occupancy), samples.deltas, distance_scale)
    index = (weights > weight_threshold).view(-1).nonzero().squeeze(1)
    points = samples.points.view(-1, 3)
    sigma = points.new_zeros(points.shape[0])
    if index.numel():
        sigma = sigma.index_put((index,), density(points.index_select(0, index)))
    return sigma.view(samples.shape)


def densities_everywhere(density: DensityFn, samples: RaySamples, occupancy: OccupancyGrid) -> Tensor:
    """``densities`` without compaction: the field is read at every sample and σ kept where the sample is inside the
    box and in an occupied cell. More lookups, but no output shape that depends on the data, so a GPU never waits
    for the host to learn how many samples survived."""
    points = samples.points.view(-1, 3)
    keep = samples.inside.view(-1)
    if occupancy.active:
        keep = keep & occupancy.query(points)
    sigma = density(points)
    return torch.where(keep, sigma, torch.zeros_like(sigma)).view(samples.shape)


def densities_until_opaque(
    density: DensityFn,
    samples: RaySamples,
    occupancy: OccupancyGrid,
    distance_scale: float,
    stop_transmittance: float,
    segment: int,
) -> Tensor:
    """``densities`` marched in segments of ``segment`` samples; a ray stops being queried once its transmittance
    falls below ``stop_transmittance`` (early ray termination: what lies behind an opaque surface cannot show)."""
    num_rays, num_samples = samples.shape
    points = samples.points.view(-1, 3)
    sigma = points.new_zeros(num_rays, num_samples)
    depth = points.new_zeros(num_rays)  # optical depth so far
    max_depth = -math.log(stop_transmittance)
    for start in range(0, num_samples, segment):
        cols = slice(start, start + segment)
        alive = depth < max_depth
        if not alive.any():
            break
        live = (samples.inside[:, cols] & alive.unsqueeze(-1)).view(-1).nonzero().squeeze(1)  # flat in [R, width]
        width = min(segment, num_samples - start)
        index = live.div(width, rounding_mode="floor") * num_samples + (live % width + start)  # flat in [R, N]
        index, selected = occupied(points, index, occupancy)
        if not index.numel():
            continue
        sigma.view(-1).index_put_((index,), density(selected))
        depth = depth + (sigma[:, cols] * samples.deltas[:, cols]).sum(dim=-1) * distance_scale
    return sigma


def shade(
    color: ColorFn,
    samples: RaySamples,
    weights: Tensor,
    threshold: float,
    view_dependent: bool,
    gradient_scale: Tensor | None = None,
) -> Tensor:
    """Ray colours [R, 3]: Σ weight · colour over the samples whose weight exceeds ``threshold`` (the others are
    treated as black: they cannot change a pixel by more than their weight). ``gradient_scale`` [R, N], if given,
    multiplies the colours' gradients per sample (Floaters No More)."""
    num_rays, num_samples = samples.shape
    index = (weights.detach().view(-1) > threshold).nonzero().squeeze(1)
    if not index.numel():
        return weights.new_zeros(num_rays, 3)
    ray_of = index.div(num_samples, rounding_mode="floor")
    directions = samples.view_directions.index_select(0, ray_of) if view_dependent else None
    colors = color(samples.points.view(-1, 3).index_select(0, index), directions)
    if gradient_scale is not None:
        colors = scale_gradient(colors, gradient_scale.view(-1, 1).index_select(0, index))
    return accumulate(weights.view(-1).index_select(0, index), colors, ray_of, num_rays)
