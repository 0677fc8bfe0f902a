"""The FourieRF field: TensoRF density and appearance grids, read through their Fourier-filtered copies.

``prepare(f_density, f_color)`` (``PreparedField``) low-passes every factor once (with autograd when training) and
keeps the result; every lookup and regulariser until the next ``prepare`` reads it. How factors are filtered and read
is the ``GridOps`` the field is given (``fields.grid_ops``): the reference one is the method as written; an
accelerated one computes the same numbers faster.

``FieldConfig`` gives every field of the package its grid's size and schedule; ZeroRF's generated factors are
configured by ``field_components.generator.ZeroRFConfig`` (``models.zerorf``).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Literal

import torch
import torch.nn.functional as F
from torch import Tensor, nn

from fourierf_plugin.field_components.activations import RevivingReLU
from fourierf_plugin.field_components.decoder import AppearanceDecoder
from fourierf_plugin.field_components.tensor_grids import TensorCP, TensorGrid, TensorVM
from fourierf_plugin.field_components.tensorf_decoder import TensoRFDecoder
from fourierf_plugin.fields.grid_ops import FilteredFactors, GridOps
from fourierf_plugin.fields.prepared_field import FilteredGrids, PreparedField

__all__ = ["ALL_AXES", "FieldConfig", "FilteredGrids", "FourierTensoRFField"]

ALL_AXES = (0, 1, 2)
"""Every world axis (x, y, z): the paper filters each factor along all of them."""


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
    decoder: Literal["few-shot", "tensorf"] = "few-shot"
    """Colour decoder: ``few-shot`` the paper's (SiLU, no encoding; the view's SH₂ when view-dependent), ``tensorf``
    TensoRF's MLP on the feature and the view direction beside their sinusoidal encodings
    (``field_components.tensorf_decoder``)."""
    feature_frequencies: int = 2
    """``tensorf`` decoder: frequencies encoding the appearance feature (TensoRF's fea_pe: 2 Blender, 0 LLFF)."""
    view_frequencies: int = 2
    """``tensorf`` decoder: frequencies encoding the view direction (TensoRF's view_pe: 2 Blender, 0 LLFF)."""
    init_scale: float | None = None
    """Std of the initial grid values; None = TensoRF's 0.1 (VM) / 0.2 (CP)."""
    density_shift: float = -10.0
    """Added to the density feature before softplus (softplus(x - 10) ≈ 4.5e-5 at 0); ReLU takes no shift."""
    density_activation: Literal["softplus", "relu"] = "softplus"
    """Density activation; TensoRF uses softplus for synthetic and ReLU for LLFF scenes."""
    revive_dead_density: bool = True
    """ReLU only: on a training batch with no positive density in a dead field (one that lit an earlier batch, or has
    been dark for ``revive_patience`` batches since its start), pass the gradient through the ReLU as if it were the
    identity; otherwise TensoRF's ReLU exactly. False = TensoRF's plain ReLU throughout."""
    revive_patience: int = 16
    """Dark training batches in a row, from the start, before a field that never lit is revived: a fresh field is
    often dark for a few batches and comes back by itself."""
    n_voxels_init: int = 128**3
    """Voxel budget at the start (per-axis resolution follows the box's aspect ratio)."""
    n_voxels_final: int = 300**3
    """Voxel budget after the last upsample."""
    upsample_fractions: tuple[float, ...] = (0.3, 0.7)
    """When to upsample, as fractions of the run (log-spaced voxel counts)."""


class FourierTensoRFField(PreparedField):
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
        mirror_boundary: bool = False,
        density_axes: Sequence[int] = ALL_AXES,
    ) -> None:
        super().__init__(aabb, ops, plane_leakage, mirror_boundary)
        self.config = config
        self.app_planes_follow_density = app_planes_follow_density
        self.density_axes = tuple(density_axes)
        grid_cls = TensorVM if config.decomposition == "vm" else TensorCP
        init = config.init_scale if config.init_scale is not None else (0.1 if config.decomposition == "vm" else 0.2)
        self.density_grid: TensorGrid = grid_cls(reso, config.density_components, init, generator)
        self.appearance_grid: TensorGrid = grid_cls(reso, config.appearance_components, init, generator)
        app_in = sum(config.appearance_components) if config.decomposition == "vm" else config.appearance_components[0]
        self.basis = nn.Linear(app_in, config.appearance_dim, bias=False)
        self.decoder: AppearanceDecoder | TensoRFDecoder = (
            TensoRFDecoder(
                config.appearance_dim, config.hidden_dim, view_dependent, config.feature_frequencies,
                config.view_frequencies,
            )
            if config.decoder == "tensorf"
            else AppearanceDecoder(config.appearance_dim, config.hidden_dim, view_dependent)
        )  # fmt: skip
        revive = config.density_activation == "relu" and config.revive_dead_density
        self.density_relu = RevivingReLU(config.revive_patience) if revive else None

    # -- filtering --------------------------------------------------------------------------------------------
    def filter(self, f_density: float, f_color: float) -> FilteredGrids:
        """Every factor low-passed at the given cutoffs (identity at f = 1); appearance planes follow the density
        cutoff where the official code's option says so, and the density factors only along ``density_axes``."""
        f_app_planes = f_density if self.app_planes_follow_density else f_color
        rendering = not torch.is_grad_enabled()

        def low_pass(grid: TensorGrid, f_planes: float, f_lines: float, axes: Sequence[int]) -> FilteredFactors:
            planes = [
                self.low_pass_plane_along(p, f_planes, spans, axes)
                for p, spans in zip(grid.planes, grid.plane_axes, strict=True)
            ]
            lines = [
                self.low_pass_lines(x, f_lines) if axis in axes else x
                for x, axis in zip(grid.lines, grid.line_axes, strict=True)
            ]
            return FilteredFactors(planes, lines, rendering)

        return FilteredGrids(
            low_pass(self.density_grid, f_density, f_density, self.density_axes),
            low_pass(self.appearance_grid, f_app_planes, f_color, ALL_AXES),
            (f_density, f_color),
        )

    # -- geometry ---------------------------------------------------------------------------------------------
    @property
    def resolution(self) -> list[int]:
        return self.density_grid.resolution

    @property
    def revived_batches(self) -> Tensor | None:
        return self.density_relu.revived if self.density_relu is not None else None

    # -- queries ----------------------------------------------------------------------------------------------
    def density(self, xyz: Tensor) -> Tensor:
        """Volume density σ ≥ 0 at world points [N, 3] -> [N]: the activated sum of the density components."""
        raw = self.ops.summed_features(self.density_grid, self.filtered.density, self.normalize(xyz))
        if self.config.density_activation == "softplus":
            return F.softplus(raw + self.config.density_shift)
        # TensoRF applies the shift to softplus only; relu(x - 10) would start dead
        return self.density_relu(raw) if self.density_relu is not None else F.relu(raw)

    def rgb(self, xyz: Tensor, directions: Tensor | None) -> Tensor:
        """Colour in [0, 1] at world points [N, 3] (directions unit [N, 3], used only when view-dependent)."""
        grid, factors, xyz = self.appearance_grid, self.filtered.appearance, self.normalize(xyz)
        if isinstance(self.decoder, TensoRFDecoder) and torch.is_grad_enabled():
            # the grid operations' training path fuses only the few-shot decoder's layers into the basis
            return self.decoder(self.basis(torch.cat(self.ops.features(grid, factors, xyz), dim=-1)), directions)
        return self.ops.appearance(grid, factors, self.basis, self.decoder, xyz, directions)  # type: ignore[arg-type]

    # -- structure and parameters ----------------------------------------------------------------------------------
    def crop(self, lo: Sequence[int], hi: Sequence[int], box: Tensor) -> None:
        """Crop the raw factors to vertices [lo, hi) per axis, which span ``box`` (the occupancy shrink)."""
        for grid in (self.density_grid, self.appearance_grid):
            grid.replace(*grid.cropped(lo, hi))
        self.aabb = box

    def upsample(self, reso: Sequence[int]) -> None:
        """Replace each raw factor by the bilinear upsample of its *filtered* version (out-of-band is dropped)."""
        for grid, factors in self._grids_with(self.filtered):
            grid.replace(*grid.upsampled(factors.planes, factors.lines, list(reso)))

    def _grids_with(self, filtered: FilteredGrids) -> tuple[tuple[TensorGrid, FilteredFactors], ...]:
        """Each raw grid beside its filtered factors (density, then appearance)."""
        return ((self.density_grid, filtered.density), (self.appearance_grid, filtered.appearance))

    def param_groups(self) -> dict[str, list[nn.Parameter]]:
        grids = list(self.density_grid.parameters()) + list(self.appearance_grid.parameters())
        return {"grids": grids, "networks": list(self.basis.parameters()) + list(self.decoder.parameters())}
