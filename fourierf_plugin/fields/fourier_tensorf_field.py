"""The FourieRF field: TensoRF density and appearance grids, read through their Fourier-filtered copies.

``prepare(f_density, f_color)`` low-passes every factor once (with autograd when training) and keeps the result;
every lookup and regulariser until the next ``prepare`` reads it. Any resize invalidates it, so a stale grid of the
old shape can never be read. ``filtered_at`` evaluates the field at other cutoffs for a while (an export, a viewer)
and then restores what was prepared.

How factors are filtered and read is the ``GridOps`` the field is given (``fields.grid_ops``): the reference one is
the method as written; an accelerated one computes the same numbers faster.
"""

from __future__ import annotations

from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from typing import Literal

import torch
import torch.nn.functional as F
from torch import Tensor, nn

from fourierf_plugin.field_components.decoder import AppearanceDecoder
from fourierf_plugin.field_components.tensor_grids import TensorCP, TensorGrid, TensorVM
from fourierf_plugin.fields.grid_ops import FilteredFactors, GridOps


@dataclass
class FieldConfig:
    """Shape of the radiance field; the CP swap is ``decomposition: cp``."""

    decomposition: Literal["vm", "cp"] = "vm"
    """VM (planes x lines, the paper's default) or CP (lines only)."""
    density_components: tuple[int, int, int] = (16, 16, 16)
    """Components per plane/line group for density (CP: all three equal)."""
    appearance_components: tuple[int, int, int] = (48, 48, 48)
    """Components per plane/line group for appearance (CP: all three equal)."""
    appearance_dim: int = 27
    """Width of the appearance feature fed to the decoder."""
    hidden_dim: int = 128
    """Decoder width."""
    init_scale: float | None = None
    """Std of the initial grid values; None = TensoRF's 0.1 (VM) / 0.2 (CP)."""
    density_shift: float = -10.0
    """Added to the density feature before softplus (softplus(x - 10) ≈ 4.5e-5 at 0); ReLU takes no shift."""
    density_activation: Literal["softplus", "relu"] = "softplus"
    """Density activation; TensoRF uses softplus for synthetic and ReLU for LLFF scenes."""
    n_voxels_init: int = 128**3
    """Voxel budget at the start (per-axis resolution follows the box's aspect ratio)."""
    n_voxels_final: int = 300**3
    """Voxel budget after the last upsample."""
    upsample_fractions: tuple[float, ...] = (0.3, 0.7)
    """When to upsample, as fractions of the run (log-spaced voxel counts)."""


@dataclass
class FilteredGrids:
    """Both grids after the low-pass at one pair of cutoffs."""

    density: FilteredFactors
    appearance: FilteredFactors
    cutoffs: tuple[float, float]


class FourierTensoRFField(nn.Module):
    def __init__(
        self,
        config: FieldConfig,
        aabb: Tensor,
        reso: list[int],
        view_dependent: bool,
        generator: torch.Generator,
        ops: GridOps | None = None,
        plane_leakage: float = 0.0,
        app_planes_follow_density: bool = False,
    ) -> None:
        super().__init__()
        self.config = config
        self.ops = ops if ops is not None else GridOps()
        self.plane_leakage = float(plane_leakage)
        self.app_planes_follow_density = app_planes_follow_density
        grid_cls = TensorVM if config.decomposition == "vm" else TensorCP
        init = config.init_scale if config.init_scale is not None else (0.1 if config.decomposition == "vm" else 0.2)
        self.density_grid: TensorGrid = grid_cls(reso, config.density_components, init, generator)
        self.appearance_grid: TensorGrid = grid_cls(reso, config.appearance_components, init, generator)
        app_in = sum(config.appearance_components) if config.decomposition == "vm" else config.appearance_components[0]
        self.basis = nn.Linear(app_in, config.appearance_dim, bias=False)
        self.decoder = AppearanceDecoder(config.appearance_dim, config.hidden_dim, view_dependent)
        self.register_buffer("aabb", aabb.detach().clone().float())
        self._filtered: FilteredGrids | None = None
        self._render_key: tuple | None = None

    # -- filtering --------------------------------------------------------------------------------------------
    def filter(self, f_density: float, f_color: float) -> FilteredGrids:
        """Every factor low-passed at the given cutoffs (identity at f = 1); appearance planes follow the density
        cutoff where the official code's option says so."""
        f_app_planes = f_density if self.app_planes_follow_density else f_color
        rendering = not torch.is_grad_enabled()

        def low_pass(grid: TensorGrid, f_planes: float, f_lines: float) -> FilteredFactors:
            planes = [self.ops.filter_planes(p, f_planes, self.plane_leakage) for p in grid.planes]
            return FilteredFactors(planes, [self.ops.filter_lines(x, f_lines) for x in grid.lines], rendering)

        return FilteredGrids(
            low_pass(self.density_grid, f_density, f_density),
            low_pass(self.appearance_grid, f_app_planes, f_color),
            (f_density, f_color),
        )

    def prepare(self, f_density: float, f_color: float) -> None:
        """Filter once for this iteration (or this render) and keep the result for every lookup.

        Without gradients (renders), a second call with the same cutoffs and unchanged parameters keeps what the
        first one made, so the views of one render share the filtering and any tables built from it.
        """
        key = (f_density, f_color, self._parameter_versions()) if not torch.is_grad_enabled() else None
        if key is not None and self._filtered is not None and self._render_key == key:
            return
        self._filtered = self.filter(f_density, f_color)
        self._render_key = key

    @contextmanager
    def filtered_at(self, f_density: float, f_color: float) -> Iterator[FilteredGrids]:
        """Evaluate the field at these cutoffs inside the block, then restore the previous filtering. The filtering is
        made without gradients (lookups in the block are as the caller's grad mode says).

        Why restore: the trainer may export between iterations, and its prepared (autograd) filtering must not
        silently become this one.
        """
        previous, previous_key = self._filtered, self._render_key
        try:
            with torch.no_grad():
                self.prepare(f_density, f_color)
            yield self.filtered
        finally:
            self._filtered, self._render_key = previous, previous_key

    def _parameter_versions(self) -> tuple:
        """Identity and in-place version of every parameter and buffer: any optimiser step or resize changes it."""
        return tuple((id(t), t._version) for t in (*self.parameters(), *self.buffers()))

    def invalidate(self) -> None:
        self._filtered = None
        self._render_key = None

    @property
    def filtered(self) -> FilteredGrids:
        if self._filtered is None:
            raise RuntimeError("field.prepare(...) must run before lookups (and after every resize)")
        return self._filtered

    # -- geometry ---------------------------------------------------------------------------------------------
    @property
    def resolution(self) -> list[int]:
        return self.density_grid.resolution

    def normalize(self, xyz: Tensor) -> Tensor:
        """World points to the grid's [-1, 1]³ (align_corners=True: the box corners are grid vertices)."""
        return (xyz - self.aabb[0]) * (2.0 / (self.aabb[1] - self.aabb[0])) - 1.0

    # -- queries ----------------------------------------------------------------------------------------------
    def density(self, xyz: Tensor) -> Tensor:
        """Volume density σ ≥ 0 at world points [N, 3] -> [N]: the activated sum of the density components."""
        raw = self.ops.summed_features(self.density_grid, self.filtered.density, self.normalize(xyz))
        if self.config.density_activation == "softplus":
            return F.softplus(raw + self.config.density_shift)
        return F.relu(raw)  # TensoRF applies the shift to softplus only; relu(x - 10) would start dead

    def rgb(self, xyz: Tensor, directions: Tensor | None) -> Tensor:
        """Colour in [0, 1] at world points [N, 3] (directions unit [N, 3], used only when view-dependent)."""
        return self.ops.appearance(
            self.appearance_grid, self.filtered.appearance, self.basis, self.decoder, self.normalize(xyz), directions
        )
