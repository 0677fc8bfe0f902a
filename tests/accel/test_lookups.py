"""The gather lookups (``accel.lookups``) read the factors exactly as the reference ``grid_sample`` does.

``GATHER`` replaces ``grid_sample`` on CPU with one ``embedding_bag`` per factor and a hand-written adjoint. Here it
gives the reference's values and gradients (for the factors and for the points) on planes and lines of awkward
sizes, at vertices, midpoints, random points and outside the box; row-major ``RowTable`` copies read the same values;
``scatter_rows`` is the adjoint of the weighted gather (both of its paths); ``corner_lookup`` is the textbook
multilinear stencil; the custom backward passes gradcheck; empty lookups keep a graph; and ``interp_volume`` is
``grid_sample``'s trilinear lookup of a dense table.
"""

from __future__ import annotations

import itertools

import pytest
import torch

from fourierf_plugin.accel.lookups import (
    GATHER,
    RowTable,
    axis_corners,
    corner_lookup,
    interp_volume,
    row_table,
    scatter_rows,
)
from fourierf_plugin.field_components.tensor_grids import GRID_SAMPLE, TensorCP, TensorVM, interp_lines, interp_plane


def _coords(size: int, seed: int) -> torch.Tensor:
    """Normalised coordinates along an axis of ``size`` vertices: every vertex, every midpoint, random points inside
    and outside [-1, 1], and the two far outside."""
    vertices = torch.linspace(-1, 1, size, dtype=torch.float64) if size > 1 else torch.zeros(1, dtype=torch.float64)
    mids = (vertices[1:] + vertices[:-1]) / 2
    rand = torch.rand(40, generator=torch.Generator().manual_seed(seed), dtype=torch.float64) * 2.6 - 1.3
    return torch.cat([vertices, mids, rand, torch.tensor([-7.0, 7.0], dtype=torch.float64)])


def _values_and_gradients(lookup, factor: torch.Tensor, coords: list[torch.Tensor], upstream: torch.Tensor):
    factor = factor.detach().clone().requires_grad_()
    coords = [c.detach().clone().requires_grad_() for c in coords]
    out = lookup(factor, *coords)
    grads = torch.autograd.grad(out, [factor, *coords], upstream)
    return out.detach(), grads


def _off_vertices(coord: torch.Tensor, size: int) -> torch.Tensor:
    """Where a coordinate lies strictly between vertices (the lookup is piecewise linear: at a vertex it has no
    derivative along that axis, and the two implementations may pick different one-sided ones). A 1-vertex axis
    reads its only vertex: constant, smooth everywhere."""
    if size == 1:
        return torch.ones_like(coord, dtype=torch.bool)
    x = (coord.clamp(-1, 1) + 1) * (size - 1) / 2
    return (x - x.round()).abs() > 1e-9


def _assert_same_lookup(ours, ref, smooth: torch.Tensor | None = None) -> None:
    """Values and the factor's gradient everywhere; the points' gradients where ``smooth`` (all by default)."""
    torch.testing.assert_close(ours[0], ref[0], atol=1e-12, rtol=0)
    torch.testing.assert_close(ours[1][0], ref[1][0], atol=1e-12, rtol=0)
    for a, b in zip(ours[1][1:], ref[1][1:], strict=True):
        keep = smooth if smooth is not None else torch.ones(a.shape[0], dtype=torch.bool)
        assert int(keep.sum()) > 10
        torch.testing.assert_close(a[keep], b[keep], atol=1e-12, rtol=0)


@pytest.mark.parametrize("shape", [(3, 6, 9), (2, 1, 5), (2, 5, 1), (4, 17, 11), (1, 2, 2)])
def test_gather_planes_equal_grid_sample_in_values_and_gradients(shape: tuple[int, int, int]) -> None:
    """Table and point gradients too: bilinear, corners aligned, border-clamped, 1-wide axes read their vertex."""
    gen = torch.Generator().manual_seed(3)
    u, v = _coords(shape[2], 1), _coords(shape[1], 2)
    n = min(u.shape[0], v.shape[0])
    u, v = u[torch.randperm(u.shape[0], generator=gen)[:n]], v[:n]
    plane = torch.randn(shape, generator=gen, dtype=torch.float64)
    upstream = torch.randn(n, shape[0], generator=gen, dtype=torch.float64)
    ours = _values_and_gradients(GATHER.plane, plane, [u, v], upstream)
    ref = _values_and_gradients(interp_plane, plane, [u, v], upstream)
    _assert_same_lookup(ours, ref, _off_vertices(u, shape[2]) & _off_vertices(v, shape[1]))
    torch.testing.assert_close(GATHER.plane(row_table(plane), u, v), ref[0], atol=1e-12, rtol=0)


@pytest.mark.parametrize("length", [1, 2, 9, 128])
def test_gather_lines_equal_grid_sample_in_values_and_gradients(length: int) -> None:
    coord = _coords(length, 5)
    gen = torch.Generator().manual_seed(5)
    line = torch.randn(4, length, generator=gen, dtype=torch.float64)
    upstream = torch.randn(coord.shape[0], 4, generator=gen, dtype=torch.float64)
    ours = _values_and_gradients(GATHER.line, line, [coord], upstream)
    ref = _values_and_gradients(interp_lines, line, [coord], upstream)
    _assert_same_lookup(ours, ref, _off_vertices(coord, length))
    torch.testing.assert_close(GATHER.line(row_table(line), coord), ref[0], atol=1e-12, rtol=0)


def test_gather_is_exact_at_vertices_in_float32() -> None:
    plane = torch.randn(3, 5, 7, generator=torch.Generator().manual_seed(0))
    rows, cols = torch.meshgrid(torch.arange(5), torch.arange(7), indexing="ij")
    u, v = cols.flatten() / 6 * 2 - 1, rows.flatten() / 4 * 2 - 1
    torch.testing.assert_close(GATHER.plane(plane, u, v), plane.reshape(3, -1).T, atol=1e-6, rtol=0)
    assert GATHER.plane(plane, u, v).dtype == torch.float32


@pytest.mark.parametrize("cls", [TensorVM, TensorCP])
def test_row_tables_give_the_same_features(cls: type) -> None:
    """Renders read pre-transposed copies (``RowTable``): the same values as the per-call transpose, bit for bit,
    and the reference's to rounding."""
    grid = cls([9, 6, 7], (3, 3, 3), 0.5, torch.Generator().manual_seed(0))
    xyz = torch.rand(200, 3, generator=torch.Generator().manual_seed(1)) * 2.2 - 1.1  # some points off the grid
    planes, lines = list(grid.planes), list(grid.lines)
    with torch.no_grad():
        plain = grid.features(planes, lines, xyz, GATHER)
        tables = grid.features([row_table(p) for p in planes], [row_table(x) for x in lines], xyz, GATHER)
        reference = grid.features(planes, lines, xyz, GRID_SAMPLE)
    for a, b, ref in zip(plain, tables, reference, strict=True):
        assert torch.equal(a, b)
        torch.testing.assert_close(a, ref, atol=1e-6, rtol=1e-5)


def test_row_table_layout() -> None:
    plane = torch.arange(24.0).view(2, 3, 4)
    table = row_table(plane)
    assert isinstance(table, RowTable) and table.shape == plane.shape
    assert table.rows.shape == (12, 2) and table.rows.is_contiguous()
    assert torch.equal(table.rows[5], plane[:, 1, 1])  # row h·W + w holds the C values of vertex (h, w)


# ------------------------------------------------------------------------------------------ gather lookup internals
def _reference_scatter(grad: torch.Tensor, columns: torch.Tensor, weights: torch.Tensor, rows: int) -> torch.Tensor:
    out = grad.new_zeros(rows, grad.shape[1])
    for n in range(columns.shape[0]):
        for k in range(columns.shape[1]):
            out[columns[n, k]] += weights[n, k] * grad[n]
    return out


@pytest.mark.parametrize("channels", [1, 5])
@pytest.mark.parametrize("index_dtype", [torch.int32, torch.int64])
@pytest.mark.parametrize("rows", [3, 40, 5000])  # few rows (sorted path) and many more rows than lookups (index_add)
def test_scatter_rows_is_the_adjoint_of_the_weighted_gather(rows: int, index_dtype: torch.dtype, channels: int) -> None:
    g = torch.Generator().manual_seed(0)
    n, k, c = 37, 4, channels
    columns = torch.randint(0, rows, (n, k), generator=g).to(index_dtype)
    weights = torch.rand(n, k, generator=g, dtype=torch.float64)
    grad = torch.randn(n, c, generator=g, dtype=torch.float64)
    expected = _reference_scatter(grad, columns, weights, rows)
    torch.testing.assert_close(scatter_rows(grad, columns, weights, rows), expected, atol=1e-12, rtol=0)


def test_scatter_rows_of_no_lookups_is_zero() -> None:
    out = scatter_rows(torch.zeros(0, 3), torch.zeros(0, 4, dtype=torch.long), torch.zeros(0, 4), 6)
    assert torch.equal(out, torch.zeros(6, 3))


@pytest.mark.parametrize("sizes", [(5,), (4, 7), (3, 1, 6), (1, 2)])
def test_corner_lookup_is_the_explicit_multilinear_stencil(sizes: tuple[int, ...]) -> None:
    """Indices and weights equal the textbook product over axes of (lower, upper) vertices, first axis fastest."""
    g = torch.Generator().manual_seed(1)
    coords = torch.rand(9, len(sizes), generator=g, dtype=torch.float64) * 2.4 - 1.2  # some outside: clamped
    axes = [axis_corners(coords[:, a], size) for a, size in enumerate(sizes)]
    strides = [int(torch.tensor(sizes[:a]).prod()) for a in range(len(sizes))]
    columns, weights = corner_lookup(axes, strides, int(torch.tensor(sizes).prod()))
    assert columns.shape == weights.shape == (9, 2 ** len(sizes))
    for n in range(9):
        for corner, bits in enumerate(itertools.product((0, 1), repeat=len(sizes))):
            bits = bits[::-1]  # corner index: first axis is the fastest-varying bit
            index, weight = 0, 1.0
            for a, (ax, bit) in enumerate(zip(axes, bits, strict=True)):
                index += (int(ax.lower[n]) + bit * ax.step) * strides[a]
                weight *= float(ax.weights[bit][n])
            assert int(columns[n, corner]) == index
            assert float(weights[n, corner]) == pytest.approx(weight, abs=1e-15)
    assert torch.allclose(weights.sum(dim=1), torch.ones(9, dtype=torch.float64))
    assert int(columns.max()) < int(torch.tensor(sizes).prod())


def test_gather_lookup_gradients_in_table_and_points_pass_gradcheck() -> None:
    """The hand-written backward (table via ``scatter_rows``, weights via the corner rows) is autograd-exact."""
    g = torch.Generator().manual_seed(3)
    plane = torch.randn(3, 4, 5, generator=g, dtype=torch.float64, requires_grad=True)
    uv = (torch.rand(6, 2, generator=g, dtype=torch.float64) * 1.8 - 0.9).requires_grad_()
    assert torch.autograd.gradcheck(lambda p, x: GATHER.plane(p, x[:, 0], x[:, 1]), (plane, uv))
    line = torch.randn(2, 7, generator=g, dtype=torch.float64, requires_grad=True)
    coord = (torch.rand(5, generator=g, dtype=torch.float64) * 1.8 - 0.9).requires_grad_()
    assert torch.autograd.gradcheck(GATHER.line, (line, coord))


def test_gather_lookup_of_no_points_is_empty_with_a_graph() -> None:
    plane = torch.randn(4, 3, 5, requires_grad=True)
    out = GATHER.plane(plane, torch.zeros(0), torch.zeros(0))
    assert out.shape == (0, 4)
    out.sum().backward()
    assert torch.equal(plane.grad, torch.zeros_like(plane))
    line = torch.randn(2, 6, requires_grad=True)
    out = GATHER.line(line, torch.zeros(0))
    assert out.shape == (0, 2)
    out.sum().backward()
    assert torch.equal(line.grad, torch.zeros_like(line))


@pytest.mark.parametrize("channels", [1, 4])
@pytest.mark.parametrize("reso", [[5, 4, 3], [1, 3, 2]])
def test_interp_volume_is_grid_samples_trilinear_lookup(channels: int, reso: list[int]) -> None:
    """The 8-corner gather reads a [Z·Y·X, D] table exactly as ``grid_sample`` reads the [D, Z, Y, X] volume
    (align_corners=True, border clamping), inside the box and outside it, in values and table gradients."""
    g = torch.Generator().manual_seed(6)
    table = torch.randn(reso[0] * reso[1] * reso[2], channels, generator=g, dtype=torch.float64)
    xyz = torch.rand(200, 3, generator=g, dtype=torch.float64) * 2.6 - 1.3
    upstream = torch.randn(200, channels, generator=g, dtype=torch.float64)

    def grid_sample_3d(t: torch.Tensor, points: torch.Tensor) -> torch.Tensor:
        volume = t.T.reshape(1, channels, reso[2], reso[1], reso[0])
        out = torch.nn.functional.grid_sample(
            volume, points.view(1, -1, 1, 1, 3), mode="bilinear", align_corners=True, padding_mode="border"
        )
        return out.view(channels, -1).T

    ours = _values_and_gradients(lambda t, p: interp_volume(t, reso, p), table, [xyz], upstream)
    ref = _values_and_gradients(grid_sample_3d, table, [xyz], upstream)
    _assert_same_lookup(ours, ref)
