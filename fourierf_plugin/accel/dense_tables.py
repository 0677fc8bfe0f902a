"""Dense vertex tables: a VM or CP grid is exactly a trilinear lookup of its vertex values.

Why: the lookups of a grid read 2 factors per component per point (6 per component for VM); a table of the summed
(density) or basis-projected (appearance) vertex values reads 8 values per point, whatever the component count.
Training rebuilds the small density table differentiably after every filtering; renders bake both tables once and
read them for every view. ``lookups.interp_volume`` reads them; the result equals the factored lookup to rounding.
"""

from __future__ import annotations

from collections.abc import Sequence

import torch
from torch import Tensor

from fourierf_plugin.field_components.tensor_grids import TensorGrid


def dense_table(
    grid: TensorGrid, planes: Sequence[Tensor], lines: Sequence[Tensor], weight: Tensor | None = None
) -> Tensor:
    """Every vertex's features projected by ``weight`` [D, ΣC] (None: summed, D = 1) -> [R2·R1·R0, D].

    ``interp_volume`` of this table is ``grid.features`` followed by the projection, up to rounding.
    """
    if not grid.plane_axes:
        return _cp_dense(lines, weight)
    if weight is None:  # the summed table (density), with or without gradients
        return _SummedVMTable.apply(*planes, *lines)
    if torch.is_grad_enabled() and any(t.requires_grad for t in (*planes, *lines, weight)):
        return _vm_dense_in_layout(planes, lines, weight, grid.resolution)
    return _vm_dense_by_slab(planes, lines, weight, grid.resolution)


class _SummedVMTable(torch.autograd.Function):
    """The summed VM table [Z, Y·X] (``dense_table`` with no projection: the density) with a hand-written backward.

    Why: autograd's backward of the same products runs MKL on transposed views, ~5x slower for these shapes, and
    keeps full-size intermediates; here every product reads contiguous operands and writes one [Z, Y, X] table.
    Groups by ``MAT_MODES``/``VEC_MODES``: A = plane xy [C, Y, X] with line z, B = plane xz [C, Z, X] with line y,
    C = plane yz [C, Z, Y] with line x.
    """

    @staticmethod
    def forward(ctx, plane_a, plane_b, plane_c, line_a, line_b, line_c):  # type: ignore[override]
        ctx.save_for_backward(plane_a, plane_b, plane_c, line_a, line_b, line_c)
        nz, ny, nx = line_a.shape[1], line_b.shape[1], line_c.shape[1]
        table = line_a.T.contiguous() @ plane_a.reshape(plane_a.shape[0], -1)  # A: [Z, C] @ [C, Y·X]
        slabs = table.view(nz, ny, nx)
        slabs.baddbmm_(line_b.T.expand(nz, -1, -1), plane_b.transpose(0, 1))  # B: [Y, C] @ [C, X] per z
        slabs.baddbmm_(plane_c.permute(1, 2, 0), line_c.expand(nz, -1, -1))  # C: [Y, C] @ [C, X] per z
        return table.view(-1, 1)

    @staticmethod
    def backward(ctx, grad):  # type: ignore[override]
        plane_a, plane_b, plane_c, line_a, line_b, line_c = ctx.saved_tensors
        nz, ny, nx = line_a.shape[1], line_b.shape[1], line_c.shape[1]
        g = grad.reshape(nz, ny, nx)
        flat, rows = g.view(nz, -1), g.view(nz * ny, nx)
        c_a, c_c = plane_a.shape[0], plane_c.shape[0]
        grad_plane_a = (line_a @ flat).view_as(plane_a)
        grad_line_a = (flat @ plane_a.reshape(c_a, -1).T).T
        grad_plane_b = torch.bmm(line_b.expand(nz, -1, -1), g).transpose(0, 1)
        grad_line_b = torch.bmm(g, plane_b.permute(1, 2, 0)).sum(dim=0).T
        grad_plane_c = (rows @ line_c.T).T.reshape(c_c, nz, ny)
        grad_line_c = plane_c.reshape(c_c, -1) @ rows
        return grad_plane_a, grad_plane_b, grad_plane_c, grad_line_a, grad_line_b, grad_line_c


def _vm_dense_in_layout(
    planes: Sequence[Tensor], lines: Sequence[Tensor], weight: Tensor, reso: Sequence[int]
) -> Tensor:
    """``dense_table`` of a projection with autograd: each group's product straight in the table's [Z, Y, X, D] layout.

    Why: a product per group in its own axis order, permuted and summed, copies the full table once more per
    group forwards and again backwards; here A and C are one matrix product each and B one batched product.
    Plane/line pairs by ``MAT_MODES``/``VEC_MODES``: A = (xy, z), B = (xz, y), C = (yz, x).
    """
    (plane_a, plane_b, plane_c), (line_a, line_b, line_c) = planes, lines
    widths, proj = _group_projections(planes, weight)
    nz = reso[2]
    d = proj[0].shape[1]
    plane_b_proj = (plane_b.unsqueeze(-1) * proj[1][:, None, None, :]).transpose(0, 1).reshape(nz, widths[1], -1)
    line_c_proj = (line_c.unsqueeze(-1) * proj[2].unsqueeze(1)).reshape(widths[2], -1)  # [C, X·D]
    # B: [Y, C] @ [Z, C, X·D]; + C: [Z, Y, C] @ [C, X·D], batched over Z (MKL runs the flat [Z·Y, C] product with
    # only X·D = 83 columns ~2x slower).
    part_bc = torch.baddbmm(
        torch.matmul(line_b.T, plane_b_proj), plane_c.permute(1, 2, 0), line_c_proj.expand(nz, -1, -1)
    ).reshape(nz, -1)
    rows_a = plane_a.reshape(widths[0], -1)  # [C, Y·X]
    part_a = torch.matmul(rows_a.T, line_a.T.unsqueeze(-1) * proj[0].unsqueeze(0))  # [Z, Y·X, D]
    return (part_bc + part_a.reshape(nz, -1)).reshape(-1, d)


def _vm_dense_by_slab(planes: Sequence[Tensor], lines: Sequence[Tensor], weight: Tensor, reso: Sequence[int]) -> Tensor:
    """``dense_table`` of a projection without gradients, one z-slab of the table at a time.

    Why: a render's appearance table is hundreds of MB; building each group's full-size product, permuting it and
    summing writes it ~5 times over, while a slab's three products stay in cache and land in the table directly.
    Plane/line pairs by ``MAT_MODES``/``VEC_MODES``: A = (xy, z), B = (xz, y), C = (yz, x).
    """
    (plane_a, plane_b, plane_c), (line_a, line_b, line_c) = planes, lines
    widths, proj = _group_projections(planes, weight)
    nx, ny, nz = reso
    d = proj[0].shape[1]
    table = plane_a.new_empty(nz, ny * nx, d)
    rows_a = plane_a.reshape(widths[0], -1).T  # [Y·X, C]
    line_c_proj = (line_c.unsqueeze(-1) * proj[2].unsqueeze(1)).reshape(widths[2], -1)  # [C, X·D]
    for z in range(nz):
        slab = table[z]
        torch.mm(rows_a, line_a[:, z : z + 1] * proj[0], out=slab)
        plane_b_proj = (plane_b[:, z, :].unsqueeze(-1) * proj[1].unsqueeze(1)).reshape(widths[1], -1)
        slab.view(ny, nx * d).addmm_(line_b.T, plane_b_proj).addmm_(plane_c[:, z, :].T, line_c_proj)
    return table.reshape(-1, d)


def _cp_dense(lines: Sequence[Tensor], weight: Tensor | None) -> Tensor:
    """``dense_table`` of a CP grid: the rank-one products of the three lines, projected."""
    c = lines[0].shape[0]
    w = _projection(weight, 0, c, lines[0])
    zy = (lines[2].unsqueeze(2) * lines[1].unsqueeze(1)).reshape(c, -1)  # [C, R2·R1]
    out = zy.T @ (lines[0].unsqueeze(-1) * w.T.unsqueeze(1)).reshape(c, -1)  # [R2·R1, R0·D]
    return out.reshape(-1, w.shape[0])


def _group_projections(planes: Sequence[Tensor], weight: Tensor) -> tuple[list[int], list[Tensor]]:
    """Each VM group's component count and its slice of the projection, transposed to [C_i, D]."""
    widths = [p.shape[0] for p in planes]
    return widths, [_projection(weight, sum(widths[:i]), c, planes[i]).T for i, c in enumerate(widths)]


def _projection(weight: Tensor | None, offset: int, count: int, like: Tensor) -> Tensor:
    """Columns [offset, offset + count) of the projection [D, ΣC], or a row of ones (a plain sum)."""
    if weight is None:
        return like.new_ones(1, count)
    return weight[:, offset : offset + count].to(like.dtype)
