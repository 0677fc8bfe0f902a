"""How the field filters, reads and regularises its factor grids: the interface, and its reference implementation.

The field and the losses call these few operations and nothing else of the tensor machinery. ``GridOps`` is the
plain form, the one to read to learn the method: ``rfft`` low-passes, ``grid_sample`` lookups, autograd throughout.
``fourierf_plugin.accel.AcceleratedOps`` overrides each with a faster form of the same arithmetic; which one a model
uses is chosen once, from its ``accel`` config, when it is built. The tests compare every override with this class.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import torch
from torch import Tensor, nn

from fourierf_plugin.field_components import fourier
from fourierf_plugin.field_components.decoder import AppearanceDecoder
from fourierf_plugin.field_components.tensor_grids import GRID_SAMPLE, FactorLookup, TensorGrid
from fourierf_plugin.model_components import losses


@dataclass
class FilteredFactors:
    """One grid's factors after the low-pass: what every lookup and regulariser of an iteration (or a render) reads."""

    planes: list[Tensor]
    lines: list[Tensor]
    rendering: bool = False
    """Filtered without gradients, for many lookups of fixed grids (a render, an export)."""
    cache: dict[str, Any] = field(default_factory=dict)
    """What a ``GridOps`` derives from these factors and reuses until they are filtered again (lookup tables)."""


class GridOps:
    """The reference operations on factor grids."""

    name = "reference"
    lookup: FactorLookup = GRID_SAMPLE
    """How ``features`` reads a factor at a point (an accelerated form sets its own)."""

    def filter_lines(self, lines: Tensor, f: float) -> Tensor:
        """Low-pass [..., L] lines at cutoff ``f`` (``fourier.filter_lines``)."""
        return fourier.filter_lines(lines, f)

    def filter_planes(self, planes: Tensor, f: float, leakage: float) -> Tensor:
        """Low-pass [..., H, W] planes at cutoff ``f`` (``fourier.filter_planes``)."""
        return fourier.filter_planes(planes, f, leakage)

    def features(self, grid: Any, factors: FilteredFactors, xyz: Tensor) -> list[Tensor]:
        """Every component's feature [N, C_i], per factor group of ``grid``, at normalised points (what a decoder that
        reads the components themselves takes, e.g. ZeroRF's)."""
        return grid.features(factors.planes, factors.lines, xyz, self.lookup)

    def summed_features(self, grid: TensorGrid, factors: FilteredFactors, xyz: Tensor) -> Tensor:
        """The sum of every component of ``grid`` at normalised points [N, 3] -> [N] (the density feature)."""
        groups = grid.features(factors.planes, factors.lines, xyz)
        return torch.stack([g.sum(dim=-1) for g in groups]).sum(dim=0)

    def appearance(
        self,
        grid: TensorGrid,
        factors: FilteredFactors,
        basis: nn.Linear,
        decoder: AppearanceDecoder,
        xyz: Tensor,
        directions: Tensor | None,
    ) -> Tensor:
        """Colour [N, 3] at normalised points: every component's feature, projected by ``basis``, decoded."""
        groups = grid.features(factors.planes, factors.lines, xyz)
        return decoder(basis(torch.cat(groups, dim=-1)), directions)

    def squared_differences(self, x: Tensor, dims: tuple[int, ...], scales: tuple[float, ...]) -> Tensor:
        """The total variation's ``Σ_k scales[k] Σ (Δ_{dims[k]} x)²`` (``losses.squared_differences``)."""
        return losses.squared_differences(x, dims, scales)
