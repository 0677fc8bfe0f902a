"""TensoRF factorisations (VM = planes x lines, CP = lines only) with per-axis resolutions.

Storage layout: plane i pairs axes ``MAT_MODES[i] = (m0, m1)`` and is stored [C, R[m1], R[m0]] so that
``grid_sample`` reads it at (x̂_m0, x̂_m1); line i runs along ``VEC_MODES[i]`` and is stored [C, R[v]]. Raw parameters
are what the optimiser updates; lookups always go through a (possibly Fourier-filtered) copy passed in explicitly,
which keeps the filtering in one place and the lookups pure.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import NamedTuple

import torch
import torch.nn.functional as F
from torch import Tensor, nn

MAT_MODES: tuple[tuple[int, int], ...] = ((0, 1), (0, 2), (1, 2))
VEC_MODES: tuple[int, ...] = (2, 1, 0)


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


def _dtype(factor: Factor) -> torch.dtype:
    return factor.rows.dtype if isinstance(factor, RowTable) else factor.dtype


def _gather_lookup(table: Factor, columns: Tensor, weights: Tensor) -> Tensor:
    """Interpolate a factor (or its row-major copy) at [N, K] corner columns with [N, K] weights -> [N, C]."""
    rows = (table if isinstance(table, RowTable) else row_table(table)).rows
    return _GatherLookup.apply(rows, columns, weights)


def _use_gather(table: Factor, coords: tuple[Tensor, ...], gather: bool | None) -> bool:
    """Row tables always gather; otherwise ``gather`` decides, else the gather path on CPU and ``grid_sample``
    elsewhere or when gradients w.r.t. the points are wanted."""
    if isinstance(table, RowTable):
        return True
    if gather is not None:
        return gather
    return table.device.type == "cpu" and not any(c.requires_grad for c in coords)


def interp_volume(table: Tensor, reso: Sequence[int], xyz: Tensor) -> Tensor:
    """Trilinear lookup of a dense vertex table [R2·R1·R0, D] (axis 0 fastest, as ``TensorGrid.dense`` lays it out)
    at normalised points [N, 3] in [-1, 1]³ (align_corners=True, border-clamped), -> [N, D].

    A VM or CP grid is exactly this lookup of its ``dense`` table: the plane's bilinear and the line's linear weights
    multiply into the trilinear ones, and every axis uses the same vertices for planes and lines. One
    ``embedding_bag`` of the 8 corners, also for one-channel tables without gradients: on CPU it is ~3x faster than
    ``grid_sample``'s 3-D kernel (300k points into P-CPU's final grid: 17 vs 57 ms).
    """
    axes = [axis_corners(xyz[:, a], reso[a]) for a in range(3)]
    columns, weights = corner_lookup(axes, (1, reso[0], reso[0] * reso[1]), table.shape[0])
    return _GatherLookup.apply(table, columns, weights.to(table.dtype))


def interp_plane(plane: Factor, u: Tensor, v: Tensor, gather: bool | None = None) -> Tensor:
    """Bilinear lookup of a [C, H, W] plane at normalised (u→W, v→H) in [-1, 1] (align_corners=True), -> [N, C].

    Returns stored values exactly at grid vertices. On CPU four row gathers (fast backward); elsewhere
    ``grid_sample`` (``gather`` forces either; both give the same values).
    """
    if not _use_gather(plane, (u, v), gather):
        grid = torch.stack([u, v], dim=-1).view(1, -1, 1, 2)
        out = F.grid_sample(plane.unsqueeze(0), grid, mode="bilinear", align_corners=True, padding_mode="border")
        return out.view(plane.shape[0], -1).T
    h, w = plane.shape[-2:]
    columns, weights = corner_lookup([axis_corners(u, w), axis_corners(v, h)], (1, w), h * w)
    return _gather_lookup(plane, columns, weights.to(_dtype(plane)))


def interp_lines(line: Factor, coord: Tensor, gather: bool | None = None) -> Tensor:
    """Linear interpolation of a [C, L] line at normalised coords in [-1, 1] (align_corners=True), -> [N, C]."""
    if not _use_gather(line, (coord,), gather):
        return interp_plane(line.unsqueeze(-1), torch.zeros_like(coord), coord, gather=False)
    columns, weights = corner_lookup([axis_corners(coord, line.shape[-1])], (1,), line.shape[-1])
    return _gather_lookup(line, columns, weights.to(_dtype(line)))


class _SummedVMTable(torch.autograd.Function):
    """The summed VM table [Z, Y·X] (``dense`` with no projection: the density) with a hand-written backward.

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


class TensorGrid(nn.Module):
    """Common state of the two factorisations: the raw parameters and their resizing."""

    planes: nn.ParameterList
    lines: nn.ParameterList

    def __init__(self) -> None:
        super().__init__()
        self.planes = nn.ParameterList()
        self.lines = nn.ParameterList()

    @property
    def resolution(self) -> list[int]:
        """Per-axis vertex counts, read back from the line lengths."""
        reso = [0, 0, 0]
        for line, axis in zip(self.lines, self.line_axes, strict=True):
            reso[axis] = int(line.shape[-1])
        return reso

    # -- queries ----------------------------------------------------------------------------------------------
    line_axes: tuple[int, ...] = VEC_MODES

    def features(self, planes: Sequence[Factor], lines: Sequence[Factor], xyz: Tensor) -> list[Tensor]:
        """Per-component features [N, C_i] for each factor group, from the given (filtered) tensors."""
        raise NotImplementedError

    def dense(self, planes: Sequence[Tensor], lines: Sequence[Tensor], weight: Tensor | None = None) -> Tensor:
        """Every vertex's features projected by ``weight`` [D, ΣC] (None: summed, D = 1) -> [R2·R1·R0, D].

        ``interp_volume`` of this table is ``features`` followed by the projection, up to rounding: one gather of
        D values per corner instead of one per component, for grids looked up many times.
        """
        raise NotImplementedError

    # -- resizing (applied to raw parameters) -----------------------------------------------------------------
    @torch.no_grad()
    def replace(self, planes: Sequence[Tensor], lines: Sequence[Tensor]) -> None:
        """Swap in new tensors (any shape) as fresh parameters, e.g. after an upsample or shrink."""
        for i, p in enumerate(planes):
            self.planes[i] = nn.Parameter(p.detach().clone().contiguous())
        for i, line in enumerate(lines):
            self.lines[i] = nn.Parameter(line.detach().clone().contiguous())

    def upsampled(self, planes: Sequence[Tensor], lines: Sequence[Tensor], reso: Sequence[int]) -> tuple[list, list]:
        """Bilinear/linear resize (align_corners=True) of the given tensors to per-axis ``reso``."""
        new_planes = [
            F.interpolate(p.unsqueeze(0), size=(reso[m1], reso[m0]), mode="bilinear", align_corners=True)[0]
            for p, (m0, m1) in zip(planes, self.plane_axes, strict=True)
        ]
        new_lines = [
            F.interpolate(line.unsqueeze(0), size=reso[a], mode="linear", align_corners=True)[0]
            for line, a in zip(lines, self.line_axes, strict=True)
        ]
        return new_planes, new_lines

    def cropped(self, lo: Sequence[int], hi: Sequence[int]) -> tuple[list, list]:
        """Raw tensors cropped to vertex index ranges [lo, hi) per axis (the AABB shrink)."""
        new_planes = [
            p[:, lo[m1] : hi[m1], lo[m0] : hi[m0]] for p, (m0, m1) in zip(self.planes, self.plane_axes, strict=True)
        ]
        new_lines = [line[:, lo[a] : hi[a]] for line, a in zip(self.lines, self.line_axes, strict=True)]
        return new_planes, new_lines

    plane_axes: tuple[tuple[int, int], ...] = MAT_MODES


class TensorVM(TensorGrid):
    """Vector-matrix split: component c of group i is ``P_i[c](x_m0, x_m1) · L_i[c](x_v)``."""

    def __init__(self, reso: Sequence[int], components: Sequence[int], init_scale: float, generator: torch.Generator):
        super().__init__()
        if len(components) != 3:
            raise ValueError(f"VM needs 3 component counts (one per plane), got {components}")
        for c, (m0, m1), v in zip(components, MAT_MODES, VEC_MODES, strict=True):
            self.planes.append(nn.Parameter(init_scale * torch.randn(c, reso[m1], reso[m0], generator=generator)))
            self.lines.append(nn.Parameter(init_scale * torch.randn(c, reso[v], generator=generator)))

    def features(self, planes: Sequence[Factor], lines: Sequence[Factor], xyz: Tensor) -> list[Tensor]:
        return [
            interp_plane(p, xyz[:, m0], xyz[:, m1]) * interp_lines(line, xyz[:, v])
            for p, line, (m0, m1), v in zip(planes, lines, MAT_MODES, VEC_MODES, strict=True)
        ]

    def dense(self, planes: Sequence[Tensor], lines: Sequence[Tensor], weight: Tensor | None = None) -> Tensor:
        if weight is None:  # the summed table (density), with or without gradients
            return _SummedVMTable.apply(*planes, *lines)
        if torch.is_grad_enabled() and any(t.requires_grad for t in (*planes, *lines, weight)):
            return self._dense_in_layout(planes, lines, weight)
        return self._dense_by_slab(planes, lines, weight)

    def _dense_in_layout(self, planes: Sequence[Tensor], lines: Sequence[Tensor], weight: Tensor) -> Tensor:
        """``dense`` of a projection with autograd: each group's product straight in the table's [Z, Y, X, D] layout.

        Why: a product per group in its own axis order, permuted and summed, copies the full table once more per
        group forwards and again backwards; here A and C are one matrix product each and B one batched product.
        Plane/line pairs by ``MAT_MODES``/``VEC_MODES``: A = (xy, z), B = (xz, y), C = (yz, x).
        """
        (plane_a, plane_b, plane_c), (line_a, line_b, line_c) = planes, lines
        widths, proj = _group_projections(planes, weight)
        nz = self.resolution[2]
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

    def _dense_by_slab(self, planes: Sequence[Tensor], lines: Sequence[Tensor], weight: Tensor) -> Tensor:
        """``dense`` of a projection without gradients, one z-slab of the table at a time.

        Why: a render's appearance table is hundreds of MB; building each group's full-size product, permuting it and
        summing writes it ~5 times over, while a slab's three products stay in cache and land in the table directly.
        Plane/line pairs by ``MAT_MODES``/``VEC_MODES``: A = (xy, z), B = (xz, y), C = (yz, x).
        """
        (plane_a, plane_b, plane_c), (line_a, line_b, line_c) = planes, lines
        widths, proj = _group_projections(planes, weight)
        nx, ny, nz = self.resolution
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


class TensorCP(TensorGrid):
    """CP: component c is ``L_x[c](x) · L_y[c](y) · L_z[c](z)``; there are no planes."""

    line_axes = (0, 1, 2)
    plane_axes = ()

    def __init__(self, reso: Sequence[int], components: Sequence[int], init_scale: float, generator: torch.Generator):
        super().__init__()
        if len(set(components)) != 1:
            raise ValueError(f"CP uses one component count for all three lines, got {components}")
        c = components[0]
        for axis in range(3):
            self.lines.append(nn.Parameter(init_scale * torch.randn(c, reso[axis], generator=generator)))

    def features(self, planes: Sequence[Factor], lines: Sequence[Factor], xyz: Tensor) -> list[Tensor]:
        out = interp_lines(lines[0], xyz[:, 0])
        for axis in (1, 2):
            out = out * interp_lines(lines[axis], xyz[:, axis])
        return [out]

    def dense(self, planes: Sequence[Tensor], lines: Sequence[Tensor], weight: Tensor | None = None) -> Tensor:
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
