"""The FourieRF field: TensoRF density and appearance grids read through their Fourier-filtered copies.

``prepare(f_density, f_color)`` filters every factor once (with autograd when training) and caches the result;
every lookup and regulariser of that iteration reuses it. Any resize invalidates the cache, so a stale grid of the
old shape can never be read.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from typing import Literal

import torch
import torch.nn.functional as F
from torch import Tensor, nn

from fourierf_plugin.field_components.decoder import AppearanceDecoder
from fourierf_plugin.field_components.fourier import filter_lines, filter_planes
from fourierf_plugin.field_components.fused_decoder import fused_decode
from fourierf_plugin.field_components.tensor_grids import (
    Factor,
    TensorCP,
    TensorGrid,
    TensorVM,
    interp_volume,
    row_table,
)
from fourierf_plugin.utils.phases import phase


@dataclass
class FilteredGrids:
    density_planes: list[Tensor]
    density_lines: list[Tensor]
    appearance_planes: list[Tensor]
    appearance_lines: list[Tensor]
    rendering: bool = False
    """Prepared without gradients for many lookups of fixed grids: they may read render-only structures."""
    dense: dict[str, Tensor | None] = dataclasses.field(default_factory=dict)
    """Per kind, the vertex table ``interp_volume`` reads instead of the factors (density: the summed feature;
    appearance: the basis output; see ``TensorGrid.dense``), or None where the field's budget says no. Built by the
    field at the kind's first lookup, so a ``prepare`` that only reads the factors (an upsample) pays nothing."""
    row_tables: dict[str, tuple[list[Factor], list[Factor]]] = dataclasses.field(default_factory=dict)
    """Per kind, row-major copies of the factors (``RowTable``) for renders on CPU, made at the first lookup."""

    def lookup_factors(self, kind: str) -> tuple[list[Factor], list[Factor]]:
        """The factors the ``kind`` ("density" or "appearance") lookups read."""
        planes, lines = getattr(self, f"{kind}_planes"), getattr(self, f"{kind}_lines")
        if not self.rendering or lines[0].device.type != "cpu":
            return planes, lines
        if kind not in self.row_tables:  # many lookups follow: transpose once instead of per call
            self.row_tables[kind] = ([row_table(p) for p in planes], [row_table(x) for x in lines])
        return self.row_tables[kind]


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
    dense_train_max_vertices: int = 1 << 22
    """In training, up to this many grid vertices the density is read from a dense table (``TensorGrid.dense``,
    rebuilt differentiably from the filtered factors after every ``prepare``): 8 values gathered per sample instead of
    6 per component, and a much cheaper backward. Larger grids, where the table costs more than the lookups it
    saves (P-CPU 128³: 0.246 -> 0.198 s/it; 256³: ~0.7 s per build), read the factors. 0 = never."""
    dense_render_max_mb: float = 512.0
    """Renders (no gradients) read density and appearance (the basis output) from dense tables, each baked when it
    fits in this many MB (4 bytes per value): exact up to rounding, far fewer values gathered. 0 = never."""


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
        self._render_key: tuple | None = None

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
        rendering = not torch.is_grad_enabled()
        key = (f_density, f_color, plane_leakage, app_follow, self._parameter_versions()) if rendering else None
        if key is not None and self._filtered is not None and self._render_key == key:
            return  # unchanged parameters and cutoffs (the views of one render): keep the tables already built
        filtered = self.filtered_grids(f_density, f_color, plane_leakage, app_follow)
        filtered.rendering = rendering
        self._filtered = filtered
        self._render_key = key

    def _dense_table(self, kind: str) -> Tensor | None:
        """The kind's dense table for this ``prepare``, built at its first lookup (None: read the factors)."""
        filtered = self.filtered
        if kind not in filtered.dense:
            with phase("dense_tables"):  # a lookup precomputation, not part of the filtering
                filtered.dense[kind] = self._bake(kind, filtered)
        return filtered.dense[kind]

    def _bake(self, kind: str, filtered: FilteredGrids) -> Tensor | None:
        """A dense table where the config's budgets allow it: density in training up to a vertex count, density and
        appearance in renders up to a size in MB."""
        vertices, cfg = math.prod(self.resolution), self.config
        mb = vertices * 4 / 2**20  # one float32 channel
        if kind == "density":
            fits = mb <= cfg.dense_render_max_mb if filtered.rendering else vertices <= cfg.dense_train_max_vertices
            return self.density_grid.dense(filtered.density_planes, filtered.density_lines) if fits else None
        if not (filtered.rendering and mb * cfg.appearance_dim <= cfg.dense_render_max_mb):
            return None
        return self.appearance_grid.dense(filtered.appearance_planes, filtered.appearance_lines, self.basis.weight)

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
        """Volume density σ ≥ 0 at world points [N, 3] -> [N]."""
        x = self.normalize(xyz)
        table = self._dense_table("density")
        if table is not None:
            raw = interp_volume(table, self.resolution, x).squeeze(-1)
        else:
            feats = self.density_grid.features(*self.filtered.lookup_factors("density"), x)
            raw = torch.stack([f.sum(dim=-1) for f in feats]).sum(dim=0)
        if self.config.density_activation == "softplus":
            return F.softplus(raw + self.config.density_shift)
        return F.relu(raw)  # TensoRF applies the shift to softplus only; relu(x - 10) would start dead

    def rgb(self, xyz: Tensor, directions: Tensor | None) -> Tensor:
        """Colour in [0, 1] at world points [N, 3] (directions unit [N, 3], used only when view-dependent)."""
        x = self.normalize(xyz)
        table = self._dense_table("appearance")
        if table is not None:
            return self._decode(interp_volume(table, self.resolution, x), directions, projected=True)
        groups = self.appearance_grid.features(*self.filtered.lookup_factors("appearance"), x)
        if torch.is_grad_enabled() and not use_bfloat16(self.config.decoder_precision, groups[0]):
            return fused_decode(groups, self.basis.weight, self.decoder, directions)  # training: the chunked MLP
        return self._decode(torch.cat(groups, dim=-1), directions, projected=False)

    def _decode(self, feats: Tensor, directions: Tensor | None, projected: bool) -> Tensor:
        """Basis (unless the dense table already applied it) and decoder, in bfloat16 where ``use_bfloat16`` says."""
        bf16 = use_bfloat16(self.config.decoder_precision, feats)
        with torch.autocast("cpu", dtype=torch.bfloat16, enabled=bf16):
            rgb = self.decoder(feats if projected else self.basis(feats), directions)
        return rgb.float() if bf16 else rgb
