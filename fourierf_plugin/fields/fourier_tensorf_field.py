"""The FourieRF field: TensoRF density and appearance grids read through their Fourier-filtered copies.

``prepare(f_density, f_color)`` filters every factor once (with autograd when training) and caches the result;
every lookup and regulariser of that iteration reuses it. Any resize invalidates the cache, so a stale grid of the
old shape can never be read.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import Literal

import torch
import torch.nn.functional as F
from torch import Tensor, nn

from fourierf_plugin.field_components.decoder import AppearanceDecoder
from fourierf_plugin.field_components.fourier import filter_lines, filter_planes
from fourierf_plugin.field_components.tensor_grids import Factor, TensorCP, TensorGrid, TensorVM, row_table


@dataclass
class FilteredGrids:
    density_planes: list[Tensor]
    density_lines: list[Tensor]
    appearance_planes: list[Tensor]
    appearance_lines: list[Tensor]
    lookup: dict[str, tuple[list[Factor], list[Factor]]] | None = None
    """Row-major copies for the lookups of an evaluation on CPU (built once per ``prepare``, see ``RowTable``)."""

    def lookup_factors(self, kind: str) -> tuple[list[Factor], list[Factor]]:
        """The factors the ``kind`` ("density" or "appearance") lookups read."""
        if self.lookup is not None:
            return self.lookup[kind]
        return getattr(self, f"{kind}_planes"), getattr(self, f"{kind}_lines")

    def with_row_tables(self) -> FilteredGrids:
        tables = {
            kind: (
                [row_table(p) for p in getattr(self, f"{kind}_planes")],
                [row_table(x) for x in getattr(self, f"{kind}_lines")],
            )
            for kind in ("density", "appearance")
        }
        return dataclasses.replace(self, lookup=tables)


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
    decoder_precision: Literal["auto", "float32", "bfloat16"] = "auto"
    """Arithmetic of the appearance basis and decoder (the grids always stay float32). auto: bfloat16 for renders
    (no gradients) on a CPU with native bf16 matmuls (the MLP is 2.7x faster there; colour error ~1e-3), float32
    otherwise. bfloat16 also in training is opt-in: on P-CPU it was no faster per run and peaked at 4.2 GB RSS."""
    n_voxels_init: int = 128**3
    """Voxel budget at the start (per-axis resolution follows the box's aspect ratio)."""
    n_voxels_final: int = 300**3
    """Voxel budget after the last upsample."""
    upsample_fractions: tuple[float, ...] = (0.3, 0.7)
    """When to upsample, as fractions of the run (log-spaced voxel counts)."""


def use_bfloat16(precision: str, features: Tensor) -> bool:
    """Whether the decoder runs in bfloat16 for these (float32, CPU) features; float64 models are never downcast."""
    if precision == "float32" or features.dtype != torch.float32 or features.device.type != "cpu":
        return False
    if precision == "bfloat16":
        return True
    return not torch.is_grad_enabled() and bool(torch.cpu._is_avx512_bf16_supported())


class FourierTensoRFField(nn.Module):
    def __init__(
        self, config: FieldConfig, aabb: Tensor, reso: list[int], view_dependent: bool, generator: torch.Generator
    ) -> None:
        super().__init__()
        self.config = config
        grid_cls = TensorVM if config.decomposition == "vm" else TensorCP
        init = config.init_scale if config.init_scale is not None else (0.1 if config.decomposition == "vm" else 0.2)
        self.density_grid: TensorGrid = grid_cls(reso, config.density_components, init, generator)
        self.appearance_grid: TensorGrid = grid_cls(reso, config.appearance_components, init, generator)
        app_in = sum(config.appearance_components) if config.decomposition == "vm" else config.appearance_components[0]
        self.basis = nn.Linear(app_in, config.appearance_dim, bias=False)
        self.decoder = AppearanceDecoder(config.appearance_dim, config.hidden_dim, view_dependent)
        self.register_buffer("aabb", aabb.detach().clone().float())
        self._filtered: FilteredGrids | None = None

    # -- filtering --------------------------------------------------------------------------------------------
    def filtered_grids(
        self, f_density: float, f_color: float, plane_leakage: float = 0.0, app_planes_follow_density: bool = False
    ) -> FilteredGrids:
        """Low-pass every factor at the given cutoffs (identity at f = 1)."""
        f_app_planes = f_density if app_planes_follow_density else f_color
        d, a = self.density_grid, self.appearance_grid
        return FilteredGrids(
            density_planes=[filter_planes(p, f_density, plane_leakage) for p in d.planes],
            density_lines=[filter_lines(line, f_density) for line in d.lines],
            appearance_planes=[filter_planes(p, f_app_planes, plane_leakage) for p in a.planes],
            appearance_lines=[filter_lines(line, f_color) for line in a.lines],
        )

    def prepare(self, f_density: float, f_color: float, plane_leakage: float = 0.0, app_follow: bool = False) -> None:
        """Filter once for this iteration (or this evaluation) and cache the result for every lookup."""
        filtered = self.filtered_grids(f_density, f_color, plane_leakage, app_follow)
        if not torch.is_grad_enabled() and self.aabb.device.type == "cpu":
            filtered = filtered.with_row_tables()  # many lookups of fixed grids follow: transpose them once
        self._filtered = filtered

    def invalidate(self) -> None:
        self._filtered = None

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
        """Volume density σ ≥ 0 at world points [N, 3] -> [N]."""
        x = self.normalize(xyz)
        feats = self.density_grid.features(*self.filtered.lookup_factors("density"), x)
        raw = torch.stack([f.sum(dim=-1) for f in feats]).sum(dim=0)
        if self.config.density_activation == "softplus":
            return F.softplus(raw + self.config.density_shift)
        return F.relu(raw)  # TensoRF applies the shift to softplus only; relu(x - 10) would start dead

    def rgb(self, xyz: Tensor, directions: Tensor | None) -> Tensor:
        """Colour in [0, 1] at world points [N, 3] (directions unit [N, 3], used only when view-dependent)."""
        x = self.normalize(xyz)
        feats = torch.cat(self.appearance_grid.features(*self.filtered.lookup_factors("appearance"), x), dim=-1)
        if not use_bfloat16(self.config.decoder_precision, feats):
            return self.decoder(self.basis(feats), directions)
        with torch.autocast("cpu", dtype=torch.bfloat16):
            return self.decoder(self.basis(feats), directions).float()
