"""The ZeroRF field: one VM grid generated from fixed noise (``field_components.generator``), read by ZeroRF's decoder.

ZeroRF (Shi et al., CVPR 2024) keeps a single feature grid of 3 × 16 channels: each group is a plane times a line,
the three groups are concatenated, and one small MLP (``field_components.zerorf_decoder``) gives both density and
colour. ``prepare`` runs the six generators once per iteration (with autograd when training; once per render
otherwise) and low-passes their outputs like any factors (the identity at f = 1: zerorf-vm has the curriculum off), so
the sampler, occupancy grid, compositing, losses, exports and checkpoints see the interface of any field.

Structure changes touch no parameter: ``upsample`` re-reads the generators' canvas at more vertices, ``crop`` narrows
the window it is read from (see the generator module), so the optimiser keeps its moments through both.

Renders read the shared layer ``W f`` through the grid operations' appearance path, which an accelerated form bakes
into a dense vertex table once per render: ``W f`` is linear in the features and a VM feature is the trilinear lookup
of its vertex values, so the table gives the same numbers (to rounding) at one 8-corner lookup per sample instead of
six factor lookups and a 48 × 64 product.
"""

from __future__ import annotations

from collections.abc import Sequence

import torch
import torch.nn.functional as F
from torch import Tensor, nn

from fourierf_plugin.field_components.generator import GeneratedVM, ZeroRFConfig
from fourierf_plugin.field_components.zerorf_decoder import ZeroRFDecoder
from fourierf_plugin.fields.grid_ops import FilteredFactors, GridOps
from fourierf_plugin.fields.prepared_field import FilteredGrids, PreparedField


class SharedLayerWeights:
    """The decoder's shared layer without its bias, in the form the grid operations take for a projection ("basis"):
    a ``weight`` [width, 3·C] and a float32 product (never autocast: the density is computed from it)."""

    def __init__(self, layer: nn.Linear) -> None:
        self.layer = layer

    @property
    def weight(self) -> Tensor:
        return self.layer.weight

    def __call__(self, features: Tensor) -> Tensor:
        with torch.autocast(features.device.type, enabled=False):
            return F.linear(features, self.layer.weight)


def _projected(projected: Tensor, directions: Tensor | None) -> Tensor:
    """The "decoder" the grid operations apply after the projection: none (the heads run afterwards, in float32)."""
    return projected


class ZeroRFField(PreparedField):
    replaces_parameters = False

    def __init__(
        self,
        config: ZeroRFConfig,
        aabb: Tensor,
        reso: Sequence[int],
        final_reso: Sequence[int],
        view_dependent: bool,
        generator: torch.Generator,
        ops: GridOps | None = None,
        plane_leakage: float = 0.0,
        mirror_boundary: bool = False,
    ) -> None:
        """``reso``: the grid at the start; ``final_reso``: the finest grid of the run (it sizes the canvas)."""
        super().__init__(aabb, ops, plane_leakage, mirror_boundary)
        self.config = config
        self.grid: GeneratedVM = config.setup(canvas_box=aabb, reso=reso, final_reso=final_reso, generator=generator)
        self.decoder = ZeroRFDecoder(3 * config.feature_channels, config.decoder_width, view_dependent, generator)
        self._shared_weights = SharedLayerWeights(self.decoder.base)

    def filter(self, f_density: float, f_color: float) -> FilteredGrids:
        """The generators' factors over the current box, low-passed at the density cutoff (one grid serves both)."""
        planes, lines = self.grid.factors(self.aabb)
        shared = FilteredFactors(
            [self.low_pass_planes(p, f_density) for p in planes],
            [self.low_pass_lines(x, f_density) for x in lines],
            rendering=not torch.is_grad_enabled(),
        )
        return FilteredGrids(shared, shared, (f_density, f_color))

    @property
    def resolution(self) -> list[int]:
        return self.grid.resolution

    def features(self, xyz: Tensor) -> Tensor:
        """The shared feature [N, 3·C] at world points: each plane × line group, concatenated."""
        groups = self.ops.features(self.grid, self.filtered.density, self.normalize(xyz))
        return torch.cat(groups, dim=-1)

    def hidden(self, xyz: Tensor) -> Tensor:
        """The decoder's shared layer ``W f + b`` [N, width] at world points (from a dense table in renders)."""
        factors = self.filtered.density
        if not factors.rendering:
            return self.decoder.hidden(self.features(xyz))
        xyz = self.normalize(xyz)
        projected = self.ops.appearance(self.grid, factors, self._shared_weights, _projected, xyz, None)  # type: ignore[arg-type]
        return projected + self.decoder.base.bias

    def density(self, xyz: Tensor) -> Tensor:
        """Volume density σ ≥ 0 at world points [N, 3] -> [N]: ZeroRF's density head."""
        return self.decoder.density(self.hidden(xyz))

    def rgb(self, xyz: Tensor, directions: Tensor | None) -> Tensor:
        """Colour at world points [N, 3] (directions unit [N, 3], used only when view-dependent)."""
        return self.decoder.rgb(self.hidden(xyz), directions)

    def crop(self, lo: Sequence[int], hi: Sequence[int], box: Tensor) -> None:
        """Read the canvas over ``box`` (vertices [lo, hi) of the current grid) from now on; nothing is regenerated."""
        self.grid.resize([h - low for low, h in zip(lo, hi, strict=True)])
        self.aabb = box

    def upsample(self, reso: Sequence[int]) -> None:
        """Regenerate the factors at ``reso`` vertices per axis (the canvas re-read, ZeroRF's grid at a new size)."""
        self.grid.resize(reso)

    def param_groups(self) -> dict[str, list[nn.Parameter]]:
        """One group, as ZeroRF trains its generators and decoder with one optimiser."""
        return {"generator": list(self.grid.parameters()) + list(self.decoder.parameters())}
