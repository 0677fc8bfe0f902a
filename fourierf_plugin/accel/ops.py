"""``AcceleratedOps``: the field's grid operations (``fields.grid_ops.GridOps``) in their fast forms.

What is chosen here, once per model from its ``AccelConfig`` and device, is everything the reference computes the
plain way:

* filters: a self-adjoint backward, and the matrix form for narrow bands (``fourier_filter``);
* lookups: on CPU one ``embedding_bag`` per factor with a sorted adjoint (``lookups``), reading row-major copies of
  the factors in renders; elsewhere the reference ``grid_sample``;
* dense vertex tables (``dense_tables``): the density in training for grids up to a vertex budget, density and
  appearance in renders within a memory budget;
* the appearance decoder as one chunked autograd function in training (``fused_decoder``), bfloat16 in renders on
  CPUs with native bf16, colour of large batches in checkpointed chunks;
* total variation with a hand-written backward (``tv``).
"""

from __future__ import annotations

import math

import torch
from torch import Tensor, nn
from torch.utils.checkpoint import checkpoint

from fourierf_plugin.accel import fourier_filter, tv
from fourierf_plugin.accel.config import AccelConfig, uses_gpu_paths
from fourierf_plugin.accel.dense_tables import dense_table
from fourierf_plugin.accel.fused_decoder import fused_decode
from fourierf_plugin.accel.lookups import GATHER, interp_volume, row_table
from fourierf_plugin.field_components.decoder import AppearanceDecoder
from fourierf_plugin.field_components.tensor_grids import GRID_SAMPLE, TensorGrid
from fourierf_plugin.fields.grid_ops import FilteredFactors, GridOps
from fourierf_plugin.utils.phases import phase


def native_bfloat16(device: torch.device) -> bool:
    """Whether bf16 matmuls run natively here (AVX-512 BF16 on CPU; the decoder is ~2.7x faster in bf16 there)."""
    return device.type == "cpu" and bool(torch.cpu._is_avx512_bf16_supported())


class AcceleratedOps(GridOps):
    name = "accelerated"

    def __init__(self, config: AccelConfig, device: torch.device | str) -> None:
        device = torch.device(device)
        self.config = config
        cpu = not uses_gpu_paths(config, device)
        self.gather = cpu  # grid_sample's CPU kernels (and its backward) are the slow part there
        self.lookup = GATHER if self.gather else GRID_SAMPLE
        precision = config.decoder_precision
        self.bf16_training = precision == "bfloat16" and cpu
        self.bf16_renders = self.bf16_training or (precision == "auto" and cpu and native_bfloat16(device))
        # The matrix form of the plane filter is rebuilt on the host whenever the cutoff moves: CPU only.
        self.matrix_filters = cpu

    filter_lines = staticmethod(fourier_filter.filter_lines)  # type: ignore[assignment]

    def filter_planes(self, planes: Tensor, f: float, leakage: float = 0.0) -> Tensor:
        return fourier_filter.filter_planes(planes, f, leakage, matrix_form=self.matrix_filters)

    def squared_differences(self, x: Tensor, dims: tuple[int, ...], scales: tuple[float, ...]) -> Tensor:
        return tv.squared_differences(x, dims, scales)

    # -- lookups ------------------------------------------------------------------------------------------------
    def summed_features(self, grid: TensorGrid, factors: FilteredFactors, xyz: Tensor) -> Tensor:
        table = self._table(factors, "density", grid, self._density_fits(grid, factors.rendering), None)
        if table is not None:
            return interp_volume(table, grid.resolution, xyz).squeeze(-1)
        groups = grid.features(*self._readable(factors), xyz, self.lookup)
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
        def colour(points: Tensor, dirs: Tensor | None) -> Tensor:
            fits = factors.rendering and self._table_mb(grid) * basis.weight.shape[0] <= self.config.dense_render_max_mb
            table = self._table(factors, "appearance", grid, fits, basis.weight)
            if table is not None:  # the basis is already applied in the table
                return self._decode(decoder, interp_volume(table, grid.resolution, points), dirs)
            groups = grid.features(*self._readable(factors), points, self.lookup)
            if torch.is_grad_enabled() and not self._bf16(groups[0].dtype):
                return fused_decode(groups, basis.weight, decoder, dirs)
            return self._decode(decoder, torch.cat(groups, dim=-1), dirs, basis)

        above, chunk = self.config.checkpoint_above, self.config.checkpoint_chunk
        if not torch.is_grad_enabled() or above <= 0 or xyz.shape[0] <= above:
            return colour(xyz, directions)
        parts = []  # many shaded samples (early in a run): keep no activations, recompute them in the backward
        for i in range(0, xyz.shape[0], chunk):
            dirs = directions[i : i + chunk] if directions is not None else None
            parts.append(checkpoint(colour, xyz[i : i + chunk], dirs, use_reentrant=False, preserve_rng_state=False))
        return torch.cat(parts)

    def _decode(
        self, decoder: AppearanceDecoder, features: Tensor, directions: Tensor | None, basis: nn.Linear | None = None
    ) -> Tensor:
        """The basis (unless a table already applied it) and the decoder, in bfloat16 where allowed."""
        bf16 = self._bf16(features.dtype)
        with torch.autocast("cpu", dtype=torch.bfloat16, enabled=bf16):
            rgb = decoder(features if basis is None else basis(features), directions)
        return rgb.float() if bf16 else rgb

    def _bf16(self, dtype: torch.dtype) -> bool:
        """bfloat16 for float32 features (float64 models are never downcast), in renders or where forced."""
        if dtype != torch.float32:
            return False
        return self.bf16_renders if not torch.is_grad_enabled() else self.bf16_training

    # -- what is derived from the filtered factors, once per filtering ------------------------------------------
    def _readable(self, factors: FilteredFactors) -> tuple[list, list]:
        """The factors, or in renders on the gather path their row-major copies (transposed once, read per view)."""
        if not (factors.rendering and self.gather):
            return factors.planes, factors.lines
        if "rows" not in factors.cache:
            factors.cache["rows"] = ([row_table(p) for p in factors.planes], [row_table(x) for x in factors.lines])
        return factors.cache["rows"]

    @staticmethod
    def _table_mb(grid: TensorGrid) -> float:
        """MB of one float32 channel over the grid's vertices."""
        return math.prod(grid.resolution) * 4 / 2**20

    def _density_fits(self, grid: TensorGrid, rendering: bool) -> bool:
        if rendering:
            return self._table_mb(grid) <= self.config.dense_render_max_mb
        # Training tables are a CPU form (gathers beat grid_sample there); a GPU reads the factors directly.
        return self.gather and math.prod(grid.resolution) <= self.config.dense_train_max_vertices

    @staticmethod
    def _table(
        factors: FilteredFactors, kind: str, grid: TensorGrid, fits: bool, weight: Tensor | None
    ) -> Tensor | None:
        """The dense table of this filtering, built at its kind's first lookup (None: read the factors)."""
        key = f"dense_{kind}"
        if key not in factors.cache:
            with phase("dense_tables"):
                factors.cache[key] = dense_table(grid, factors.planes, factors.lines, weight) if fits else None
        return factors.cache[key]


def build_ops(config: AccelConfig, device: torch.device | str) -> GridOps:
    """The grid operations a model uses, chosen once when it is built."""
    if config.backend == "reference-grid-ops":
        return GridOps()
    return AcceleratedOps(config, device)
