"""Factor and table lookups as one fused gather per point: ``embedding_bag`` over the 2, 4 or 8 corners.

Why: on CPU ``embedding_bag`` computes the weighted sum of the corner rows in one pass (~5x faster than one gather
and one multiply per corner, and faster than ``grid_sample``'s CPU kernels), and ``scatter_rows`` is its fast
adjoint. The values are ``grid_sample``'s (bilinear, corners aligned, border-clamped): the tests compare both.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import NamedTuple

import torch
import torch.nn.functional as F
from torch import Tensor


class AxisCorners(NamedTuple):
    """Linear interpolation along one axis: the lower vertex [N], the stride to the upper one (0 for a 1-vertex axis,
    1 otherwise) and the weights of the lower and upper vertex ([N] each)."""

    lower: Tensor
    step: int
    weights: tuple[Tensor, Tensor]


def axis_corners(coord: Tensor, size: int) -> AxisCorners:
    """Corners of normalised coords in [-1, 1] (align_corners=True, clamped to the border like
    ``padding_mode="border"``). A 1-vertex axis reads its only vertex."""
    x = ((coord + 1.0) * (0.5 * (size - 1))).clamp(0, size - 1)
    lower = x.floor().clamp(max=max(size - 2, 0))
    frac = x - lower
    return AxisCorners(lower.int(), min(size - 1, 1), (1.0 - frac, frac))


def corner_lookup(axes: Sequence[AxisCorners], strides: Sequence[int], rows: int) -> tuple[Tensor, Tensor]:
    """Row indices [N, 2^d] and weights [N, 2^d] of the multilinear lookup over ``axes`` (first axis fastest) in a
    row-major table of ``rows`` rows whose axis strides are ``strides``.

    The indices are one base row plus fixed corner offsets (one broadcast); the weights are products of [N] columns
    stacked once: a broadcast product over 2-wide rows runs ~3x slower on CPU. Indices are int32 where the table
    allows (the lookups and the backward's sort run on half the bytes).
    """
    index_dtype = torch.int32 if rows < 2**31 else torch.int64
    base = axes[0].lower.to(index_dtype) * strides[0]
    offsets = [0, axes[0].step * strides[0]]
    weights = list(axes[0].weights)
    for ax, stride in zip(axes[1:], strides[1:], strict=True):
        base = base + ax.lower.to(index_dtype) * stride
        offsets = [o + corner * ax.step * stride for corner in (0, 1) for o in offsets]
        weights = [w_ax * w for w_ax in ax.weights for w in weights]
    columns = base.unsqueeze(1) + torch.tensor(offsets, dtype=index_dtype, device=base.device)
    return columns, torch.stack(weights, dim=1)


def scatter_rows(grad: Tensor, columns: Tensor, weights: Tensor, rows: int) -> Tensor:
    """The adjoint of the weighted row gather: ``out[m] = Σ_{(n, k): columns[n, k] = m} weights[n, k] · grad[n]``.

    Why two paths: CPU ``index_add_`` writes one row at a time. When there are many more lookups than table rows
    (plane and line factors) it is ~3x faster to sort the lookups by row once and let ``embedding_bag`` sum each
    row's contributions; for huge tables read sparsely (a dense vertex table) the sort's per-row offsets cost more
    than they save, and one flat ``index_add_`` wins.
    """
    n, k = columns.shape
    flat = columns.reshape(-1)
    if rows > n * k:
        flat = flat.long()  # CPU index_add_ takes a ~5x slower path with int32 indices
        if grad.shape[1] == 1:  # one channel: a 1-D accumulation, ~2x faster than into [rows, 1]
            return grad.new_zeros(rows).index_add_(0, flat, (grad * weights).reshape(-1)).unsqueeze(1)
        values = (grad.unsqueeze(1) * weights.unsqueeze(-1)).reshape(n * k, grad.shape[1])
        return grad.new_zeros(rows, grad.shape[1]).index_add_(0, flat, values)
    ordered, order = torch.sort(flat, stable=True)  # stable: the sums run in one fixed order (reproducible runs)
    offsets = torch.searchsorted(ordered, torch.arange(rows, dtype=flat.dtype, device=flat.device))
    points = order.div(k, rounding_mode="floor")
    return F.embedding_bag(points, grad, offsets, mode="sum", per_sample_weights=weights.reshape(-1)[order])


class _GatherLookup(torch.autograd.Function):
    """``Σ_k weights[:, k] · table[columns[:, k]]`` for a row-major [M, C] table, with a hand-written backward.

    Why: on CPU ``embedding_bag`` computes the weighted sum of rows in one fused pass (~5x faster than a gather and
    a multiply per corner), and ``scatter_rows`` is its fast adjoint (``grid_sample``'s CPU backward scatters one
    point at a time; ``embedding_bag``'s own backward is slower than either path of ``scatter_rows``).
    """

    @staticmethod
    def forward(ctx, table: Tensor, columns: Tensor, weights: Tensor) -> Tensor:  # type: ignore[override]
        ctx.save_for_backward(table, columns, weights)
        return F.embedding_bag(columns, table, mode="sum", per_sample_weights=weights)

    @staticmethod
    def backward(ctx, grad: Tensor) -> tuple[Tensor | None, None, Tensor | None]:  # type: ignore[override]
        table, columns, weights = ctx.saved_tensors
        grad = grad.contiguous()
        grad_table = scatter_rows(grad, columns, weights, table.shape[0]) if ctx.needs_input_grad[0] else None
        grad_weights = None
        if ctx.needs_input_grad[2]:  # d out / d weights[n, k] = table[columns[n, k]]: gradients w.r.t. the points
            corners = table.index_select(0, columns.reshape(-1)).view(*columns.shape, -1)
            grad_weights = (corners * grad.unsqueeze(1)).sum(dim=-1)
        return grad_table, None, grad_weights


class RowTable(NamedTuple):
    """A plane [C, H, W] or line [C, L] already laid out row-major as [H·W or L, C] for the gather path.

    Why: the transpose costs as much as a lookup; an evaluation render looks the same grids up thousands of times,
    so it transposes once (``row_table``) instead of per call.
    """

    rows: Tensor
    shape: torch.Size


def row_table(factor: Tensor) -> RowTable:
    return RowTable(factor.reshape(factor.shape[0], -1).T.contiguous(), factor.shape)


Factor = Tensor | RowTable


def _rows(factor: Factor) -> Tensor:
    return factor.rows if isinstance(factor, RowTable) else row_table(factor).rows


class GatherLookup:
    """A ``FactorLookup`` (``field_components.tensor_grids``) through ``_GatherLookup``; reads factors or their
    ``RowTable`` copies."""

    def plane(self, plane: Factor, u: Tensor, v: Tensor) -> Tensor:
        rows = _rows(plane)
        h, w = plane.shape[-2:]
        columns, weights = corner_lookup([axis_corners(u, w), axis_corners(v, h)], (1, w), h * w)
        return _GatherLookup.apply(rows, columns, weights.to(rows.dtype))

    def line(self, line: Factor, coord: Tensor) -> Tensor:
        rows = _rows(line)
        length = line.shape[-1]
        columns, weights = corner_lookup([axis_corners(coord, length)], (1,), length)
        return _GatherLookup.apply(rows, columns, weights.to(rows.dtype))


GATHER = GatherLookup()


def interp_volume(table: Tensor, reso: Sequence[int], xyz: Tensor) -> Tensor:
    """Trilinear lookup of a dense vertex table [R2·R1·R0, D] (axis 0 fastest, as ``dense_tables.dense_table`` lays
    it out) at normalised points [N, 3] in [-1, 1]³ (align_corners=True, border-clamped), -> [N, D].

    A VM or CP grid is exactly this lookup of its dense table: the plane's bilinear and the line's linear weights
    multiply into the trilinear ones, and every axis uses the same vertices for planes and lines. One
    ``embedding_bag`` of the 8 corners, also for one-channel tables without gradients: on CPU it is ~3x faster than
    ``grid_sample``'s 3-D kernel (300k points into P-CPU's final grid: 17 vs 57 ms).
    """
    axes = [axis_corners(xyz[:, a], reso[a]) for a in range(3)]
    columns, weights = corner_lookup(axes, (1, reso[0], reso[0] * reso[1]), table.shape[0])
    return _GatherLookup.apply(table, columns, weights.to(table.dtype))
