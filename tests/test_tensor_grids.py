"""Properties of the TensoRF factorisations and their lookups (spec 3.1, 7.8: align_corners=True everywhere)."""

from __future__ import annotations

import itertools

import pytest
import torch
from torch import nn

from fourierf_plugin.field_components.tensor_grids import (
    MAT_MODES,
    VEC_MODES,
    RowTable,
    TensorCP,
    TensorVM,
    axis_corners,
    corner_lookup,
    interp_lines,
    interp_plane,
    interp_volume,
    row_table,
    scatter_rows,
)

RESO = (5, 7, 9)


def _gen(seed: int = 0) -> torch.Generator:
    return torch.Generator().manual_seed(seed)


def _vertex_coord(i: int, n: int) -> float:
    """Normalised coordinate of vertex i of n with align_corners=True."""
    return -1.0 + 2.0 * i / (n - 1)


def _rand_points(n: int, seed: int = 1) -> torch.Tensor:
    return torch.rand(n, 3, generator=_gen(seed)) * 2.0 - 1.0


# ------------------------------------------------------------------------------------------------ interpolation
@pytest.mark.parametrize("length", [2, 3, 7, 9])
def test_interp_lines_exact_at_vertices(length: int) -> None:
    line = torch.randn(4, length, generator=_gen())
    coord = torch.tensor([_vertex_coord(i, length) for i in range(length)])
    out = interp_lines(line, coord)
    assert out.shape == (length, 4)
    torch.testing.assert_close(out, line.T, atol=1e-6, rtol=0)


def test_interp_lines_vertices_of_a_long_line() -> None:
    """At L = 128 a float32 vertex coordinate is itself off by ~L·eps, so the lookup is exact only up to that.

    float64 coordinates give the stored values to 1e-12; float32 ones err by at most a few ulp of the vertex index
    times the neighbouring difference, exactly like TensoRF's grid_sample.
    """
    length = 128
    line = torch.randn(4, length, generator=_gen())
    coord64 = torch.tensor([_vertex_coord(i, length) for i in range(length)], dtype=torch.float64)
    torch.testing.assert_close(interp_lines(line.double(), coord64), line.T.double(), atol=1e-12, rtol=0)
    coord = coord64.float()
    out = interp_lines(line, coord)
    grid = torch.stack([torch.zeros_like(coord), coord], dim=-1).view(1, -1, 1, 2)
    ref = torch.nn.functional.grid_sample(line[None, :, :, None], grid, mode="bilinear", align_corners=True)
    torch.testing.assert_close(out, ref.view(4, -1).T, atol=1e-6, rtol=0)
    max_step = float((line[:, 1:] - line[:, :-1]).abs().max())
    bound = 8 * length * torch.finfo(torch.float32).eps * max_step
    assert float((out - line.T).abs().max()) <= bound


def test_interp_lines_midway_is_average() -> None:
    line = torch.randn(3, 6, generator=_gen())
    mids = torch.tensor([(_vertex_coord(i, 6) + _vertex_coord(i + 1, 6)) / 2 for i in range(5)])
    expected = 0.5 * (line[:, :-1] + line[:, 1:])
    torch.testing.assert_close(interp_lines(line, mids), expected.T, atol=1e-6, rtol=0)


def test_interp_lines_matches_grid_sample() -> None:
    """The gather + lerp must agree with TensoRF's grid_sample on a [1, C, L, 1] image (spec 3.1)."""
    line = torch.randn(5, 11, generator=_gen())
    coord = torch.rand(200, generator=_gen(2)) * 2 - 1
    grid = torch.stack([torch.zeros_like(coord), coord], dim=-1).view(1, -1, 1, 2)
    ref = torch.nn.functional.grid_sample(line[None, :, :, None], grid, mode="bilinear", align_corners=True)
    torch.testing.assert_close(interp_lines(line, coord), ref.view(5, -1).T, atol=1e-6, rtol=0)


def test_interp_lines_single_vertex_returns_value() -> None:
    line = torch.tensor([[2.5], [-1.0]])
    out = interp_lines(line, torch.tensor([-1.0, 0.0, 0.3, 1.0]))
    assert out.shape == (4, 2)
    assert (out == torch.tensor([2.5, -1.0])).all()


def test_interp_lines_clamps_outside_range() -> None:
    line = torch.arange(5.0).view(1, 5)
    out = interp_lines(line, torch.tensor([-3.0, -1.0, 1.0, 4.0]))[:, 0]
    assert out.tolist() == [0.0, 0.0, 4.0, 4.0]


@pytest.mark.parametrize(("h", "w"), [(7, 5), (5, 9), (9, 7), (4, 4)])
def test_interp_plane_exact_at_vertices_non_square(h: int, w: int) -> None:
    plane = torch.randn(3, h, w, generator=_gen())
    rows, cols = torch.meshgrid(torch.arange(h), torch.arange(w), indexing="ij")
    u = torch.tensor([_vertex_coord(int(c), w) for c in cols.flatten()])
    v = torch.tensor([_vertex_coord(int(r), h) for r in rows.flatten()])
    out = interp_plane(plane, u, v)
    assert out.shape == (h * w, 3)
    torch.testing.assert_close(out, plane.reshape(3, -1).T, atol=1e-6, rtol=0)


def test_interp_plane_bilinear_midpoint_is_average_of_four() -> None:
    plane = torch.randn(2, 5, 7, generator=_gen())
    u = torch.tensor([(_vertex_coord(2, 7) + _vertex_coord(3, 7)) / 2])
    v = torch.tensor([(_vertex_coord(1, 5) + _vertex_coord(2, 5)) / 2])
    expected = plane[:, 1:3, 2:4].mean(dim=(-2, -1))
    torch.testing.assert_close(interp_plane(plane, u, v)[0], expected, atol=1e-6, rtol=0)


# --------------------------------------------------------------------------------------------------- VM / CP
def test_vm_layout_and_resolution() -> None:
    vm = TensorVM(RESO, (2, 3, 4), 0.1, _gen())
    for p, line, (m0, m1), v, c in zip(vm.planes, vm.lines, MAT_MODES, VEC_MODES, (2, 3, 4), strict=True):
        assert p.shape == (c, RESO[m1], RESO[m0])
        assert line.shape == (c, RESO[v])
    assert vm.resolution == list(RESO)


def test_cp_layout_and_resolution() -> None:
    cp = TensorCP(RESO, (6, 6, 6), 0.2, _gen())
    assert len(cp.planes) == 0
    assert [tuple(line.shape) for line in cp.lines] == [(6, 5), (6, 7), (6, 9)]
    assert cp.resolution == list(RESO)


def test_bad_component_counts_raise() -> None:
    with pytest.raises(ValueError):
        TensorVM(RESO, (2, 3), 0.1, _gen())
    with pytest.raises(ValueError):
        TensorCP(RESO, (2, 3, 2), 0.1, _gen())


def test_init_scale_is_std() -> None:
    vm = TensorVM((40, 40, 40), (16, 16, 16), 0.1, _gen())
    values = torch.cat([p.detach().flatten() for p in vm.planes])
    assert abs(float(values.std()) - 0.1) < 0.005


def test_vm_features_at_vertices_are_plane_times_line() -> None:
    vm = TensorVM(RESO, (2, 3, 4), 0.1, _gen())
    idx = torch.tensor(list(itertools.product(range(RESO[0]), range(RESO[1]), range(RESO[2]))))
    xyz = torch.stack([-1.0 + 2.0 * idx[:, a].float() / (RESO[a] - 1) for a in range(3)], dim=-1)
    feats = vm.features(list(vm.planes), list(vm.lines), xyz)
    for f, p, line, (m0, m1), v in zip(feats, vm.planes, vm.lines, MAT_MODES, VEC_MODES, strict=True):
        expected = p[:, idx[:, m1], idx[:, m0]] * line[:, idx[:, v]]
        assert f.shape == (idx.shape[0], p.shape[0])
        torch.testing.assert_close(f, expected.T, atol=1e-6, rtol=1e-6)


def test_vm_features_product_structure_off_grid() -> None:
    vm = TensorVM(RESO, (2, 3, 4), 0.1, _gen())
    xyz = _rand_points(300)
    feats = vm.features(list(vm.planes), list(vm.lines), xyz)
    for f, p, line, (m0, m1), v in zip(feats, vm.planes, vm.lines, MAT_MODES, VEC_MODES, strict=True):
        grid = torch.stack([xyz[:, m0], xyz[:, m1]], dim=-1).view(1, -1, 1, 2)
        ref_p = torch.nn.functional.grid_sample(p[None], grid, align_corners=True).view(p.shape[0], -1).T
        lg = torch.stack([torch.zeros_like(xyz[:, v]), xyz[:, v]], dim=-1).view(1, -1, 1, 2)
        ref_l = torch.nn.functional.grid_sample(line[None, :, :, None], lg, align_corners=True)
        torch.testing.assert_close(f, ref_p * ref_l.view(line.shape[0], -1).T, atol=1e-6, rtol=1e-5)


def test_vm_features_use_the_given_tensors_not_the_parameters() -> None:
    vm = TensorVM(RESO, (2, 2, 2), 0.1, _gen())
    planes = [torch.ones_like(p) for p in vm.planes]
    lines = [torch.full_like(line, 3.0) for line in vm.lines]
    for f in vm.features(planes, lines, _rand_points(10)):
        torch.testing.assert_close(f, torch.full_like(f, 3.0))


def test_cp_features_product_of_three_lines() -> None:
    cp = TensorCP(RESO, (4, 4, 4), 0.2, _gen())
    xyz = _rand_points(100)
    (feat,) = cp.features([], list(cp.lines), xyz)
    expected = (
        interp_lines(cp.lines[0], xyz[:, 0])
        * interp_lines(cp.lines[1], xyz[:, 1])
        * interp_lines(cp.lines[2], xyz[:, 2])
    )
    assert feat.shape == (100, 4)
    torch.testing.assert_close(feat, expected)
    # At a vertex: the plain product of the stored entries.
    i, j, k = 1, 5, 8
    at = torch.tensor([[_vertex_coord(i, 5), _vertex_coord(j, 7), _vertex_coord(k, 9)]])
    direct = cp.lines[0][:, i] * cp.lines[1][:, j] * cp.lines[2][:, k]
    torch.testing.assert_close(cp.features([], list(cp.lines), at)[0][0], direct, atol=1e-6, rtol=1e-6)


@pytest.mark.parametrize("cls", [TensorVM, TensorCP])
def test_features_gradients_finite(cls: type) -> None:
    grid = cls(RESO, (3, 3, 3), 0.1, _gen())
    xyz = _rand_points(64)
    loss = sum(f.square().sum() for f in grid.features(list(grid.planes), list(grid.lines), xyz))
    loss.backward()
    for p in [*grid.planes, *grid.lines]:
        assert p.grad is not None and torch.isfinite(p.grad).all()
        assert p.grad.abs().sum() > 0


# ------------------------------------------------------------------------------------------------- resizing
def _linear_vm(reso: tuple[int, int, int]) -> TensorVM:
    """A VM grid whose planes and lines are linear in the normalised coordinates (exactly preserved by upsampling)."""
    vm = TensorVM(reso, (2, 2, 2), 0.1, _gen())
    with torch.no_grad():
        for p, (m0, m1) in zip(vm.planes, MAT_MODES, strict=True):
            v = torch.linspace(-1, 1, reso[m1])[:, None]
            u = torch.linspace(-1, 1, reso[m0])[None, :]
            p[0] = 0.5 + 2.0 * u - 1.5 * v
            p[1] = -u + 0.25 * v
        for line, a in zip(vm.lines, VEC_MODES, strict=True):
            t = torch.linspace(-1, 1, reso[a])
            line[0] = 1.0 + 3.0 * t
            line[1] = -2.0 * t
    return vm


def test_upsampled_shapes_and_linear_functions_preserved() -> None:
    vm = _linear_vm(RESO)
    target = (9, 12, 17)
    planes, lines = vm.upsampled(list(vm.planes), list(vm.lines), target)
    for p, (m0, m1) in zip(planes, MAT_MODES, strict=True):
        assert p.shape == (2, target[m1], target[m0])
    for line, a in zip(lines, VEC_MODES, strict=True):
        assert line.shape == (2, target[a])
    # The same function on the new grid: features at random points agree with the coarse grid.
    xyz = _rand_points(200)
    before = vm.features(list(vm.planes), list(vm.lines), xyz)
    after = vm.features(planes, lines, xyz)
    for b, a in zip(before, after, strict=True):
        torch.testing.assert_close(a, b, atol=1e-5, rtol=1e-5)
    # And directly: the new vertices hold the linear function's values.
    v = torch.linspace(-1, 1, target[1])[:, None]
    u = torch.linspace(-1, 1, target[0])[None, :]
    torch.testing.assert_close(planes[0][0], 0.5 + 2.0 * u - 1.5 * v, atol=1e-5, rtol=0)


def test_upsampled_cp_lines() -> None:
    cp = TensorCP(RESO, (2, 2, 2), 0.2, _gen())
    with torch.no_grad():
        for a, line in enumerate(cp.lines):
            line.copy_(torch.linspace(-1, 1, RESO[a]).expand(2, -1) * (a + 1))
    planes, lines = cp.upsampled([], list(cp.lines), (11, 13, 3))
    assert planes == []
    assert [tuple(line.shape) for line in lines] == [(2, 11), (2, 13), (2, 3)]
    torch.testing.assert_close(lines[1][0], 2 * torch.linspace(-1, 1, 13), atol=1e-6, rtol=0)


def test_upsampled_does_not_modify_parameters() -> None:
    vm = TensorVM(RESO, (2, 2, 2), 0.1, _gen())
    before = [p.detach().clone() for p in vm.planes]
    vm.upsampled(list(vm.planes), list(vm.lines), (10, 10, 10))
    assert all(torch.equal(a, b) for a, b in zip(before, vm.planes, strict=True))
    assert vm.resolution == list(RESO)


def test_cropped_index_ranges_vm() -> None:
    vm = TensorVM(RESO, (2, 2, 2), 0.1, _gen())
    lo, hi = [1, 2, 3], [4, 6, 8]
    planes, lines = vm.cropped(lo, hi)
    for new, old, (m0, m1) in zip(planes, vm.planes, MAT_MODES, strict=True):
        assert new.shape == (2, hi[m1] - lo[m1], hi[m0] - lo[m0])
        assert torch.equal(new, old[:, lo[m1] : hi[m1], lo[m0] : hi[m0]])
    for new, old, a in zip(lines, vm.lines, VEC_MODES, strict=True):
        assert torch.equal(new, old[:, lo[a] : hi[a]])
    # After replacing, the vertex (lo) of the old grid is vertex 0 of the new one.
    vm2 = TensorVM(RESO, (2, 2, 2), 0.1, _gen())
    vm2.replace(planes, lines)
    assert vm2.resolution == [3, 4, 5]
    assert torch.equal(vm2.planes[1][:, 0, 0], vm.planes[1][:, lo[2], lo[0]])


def test_cropped_cp() -> None:
    cp = TensorCP(RESO, (2, 2, 2), 0.2, _gen())
    planes, lines = cp.cropped([1, 0, 2], [3, 7, 5])
    assert planes == []
    for a, (new, old) in enumerate(zip(lines, cp.lines, strict=True)):
        assert torch.equal(new, old[:, [1, 0, 2][a] : [3, 7, 5][a]])


@pytest.mark.parametrize("cls", [TensorVM, TensorCP])
def test_replace_makes_fresh_leaf_parameters(cls: type) -> None:
    grid = cls(RESO, (2, 2, 2), 0.1, _gen())
    old_ids = [id(p) for p in grid.parameters()]
    planes, lines = grid.upsampled(list(grid.planes), list(grid.lines), (8, 10, 12))
    # Inputs carrying autograd history must not leak it into the new parameters.
    planes = [p * 1.0 for p in planes]
    grid.replace(planes, lines)
    assert grid.resolution == [8, 10, 12]
    params = list(grid.parameters())
    assert len(params) == len(old_ids)
    for p in params:
        assert isinstance(p, nn.Parameter) and p.is_leaf and p.requires_grad and p.grad_fn is None
        assert id(p) not in old_ids
    for p, src in zip(grid.planes, planes, strict=True):
        assert torch.equal(p.detach(), src.detach())
        assert p.data_ptr() != src.data_ptr()  # a copy, not a view of the caller's tensor
    # The new parameters train.
    loss = sum(f.sum() for f in grid.features(list(grid.planes), list(grid.lines), _rand_points(8)))
    loss.backward()
    assert all(p.grad is not None for p in grid.parameters())


@pytest.mark.parametrize("shape", [(3, 6, 9), (2, 1, 5), (2, 5, 1), (4, 17, 11)])
def test_gather_and_grid_sample_planes_agree_in_values_and_gradients(shape: tuple[int, int, int]) -> None:
    """The CPU lookup (row gathers + index_add backward) is grid_sample's bilinear lookup, inside and outside."""
    gen = torch.Generator().manual_seed(3)
    u, v = torch.rand(2, 300, generator=gen, dtype=torch.float64) * 2.4 - 1.2
    grad = torch.randn(300, shape[0], generator=gen, dtype=torch.float64)
    results = []
    for gather in (True, False):
        plane = torch.randn(shape, generator=torch.Generator().manual_seed(1), dtype=torch.float64).requires_grad_()
        out = interp_plane(plane, u, v, gather=gather)
        out.backward(grad)
        results.append((out.detach(), plane.grad))
    torch.testing.assert_close(results[0][0], results[1][0], atol=1e-12, rtol=0)
    torch.testing.assert_close(results[0][1], results[1][1], atol=1e-12, rtol=0)


@pytest.mark.parametrize("length", [1, 2, 9])
def test_gather_and_grid_sample_lines_agree_in_values_and_gradients(length: int) -> None:
    coord = torch.linspace(-1.3, 1.3, 57, dtype=torch.float64)
    grad = torch.randn(57, 4, generator=torch.Generator().manual_seed(5), dtype=torch.float64)
    results = []
    for gather in (True, False):
        line = torch.randn(4, length, generator=torch.Generator().manual_seed(2), dtype=torch.float64)
        line.requires_grad_()
        out = interp_lines(line, coord, gather=gather)
        out.backward(grad)
        results.append((out.detach(), line.grad))
    torch.testing.assert_close(results[0][0], results[1][0], atol=1e-12, rtol=0)
    torch.testing.assert_close(results[0][1], results[1][1], atol=1e-12, rtol=0)


@pytest.mark.parametrize("cls", [TensorVM, TensorCP])
def test_row_tables_give_the_same_features(cls: type) -> None:
    """Evaluation reads pre-transposed copies (``RowTable``): same values as the per-call transpose, bit for bit."""
    grid = cls([9, 6, 7], (3, 3, 3), 0.5, torch.Generator().manual_seed(0))
    xyz = torch.rand(200, 3, generator=torch.Generator().manual_seed(1)) * 2.2 - 1.1  # some points off the grid
    planes, lines = list(grid.planes), list(grid.lines)
    with torch.no_grad():
        plain = grid.features(planes, lines, xyz)
        tables = grid.features([row_table(p) for p in planes], [row_table(x) for x in lines], xyz)
    for a, b in zip(plain, tables, strict=True):
        assert torch.equal(a, b)


def test_row_tables_are_built_only_for_evaluation() -> None:
    from fourierf_plugin.fields.fourier_tensorf_field import FieldConfig, FourierTensoRFField

    field = FourierTensoRFField(
        FieldConfig(density_components=(2, 2, 2), appearance_components=(2, 2, 2), dense_render_max_mb=0),
        torch.tensor([[-1.0] * 3, [1.0] * 3]), [5, 6, 7], False, torch.Generator().manual_seed(0),
    )  # fmt: skip
    field.prepare(0.5, 0.5)
    assert not any(isinstance(t, RowTable) for t in field.filtered.lookup_factors("density")[0])  # training
    with torch.no_grad():
        field.prepare(0.5, 0.5)
    assert field.filtered.row_tables == {}  # made at the first lookup, not before
    assert all(isinstance(t, RowTable) for t in field.filtered.lookup_factors("density")[0])
    assert set(field.filtered.row_tables) == {"density"}
    xyz = torch.rand(50, 3) * 2 - 1
    with torch.no_grad():
        evaluated = field.density(xyz)
    field.prepare(0.5, 0.5)
    torch.testing.assert_close(field.density(xyz).detach(), evaluated)


# --------------------------------------------------------------------------------------------- dense vertex tables
def _grid64(cls: type, reso: list[int]) -> TensorVM | TensorCP:
    comps = (3, 4, 2) if cls is TensorVM else (4, 4, 4)
    return cls(reso, comps, 0.7, torch.Generator().manual_seed(4)).double()


@pytest.mark.parametrize("cls", [TensorVM, TensorCP])
@pytest.mark.parametrize("reso", [[5, 6, 7], [2, 9, 3], [1, 4, 6]])
def test_dense_table_lookup_is_the_factored_lookup(cls: type, reso: list[int]) -> None:
    """Bilinear plane x linear line = trilinear on the vertex products: the baked table reads the same field,
    inside the box and clamped outside, summed (density) or projected (the appearance basis)."""
    grid = _grid64(cls, reso)
    planes, lines = list(grid.planes), list(grid.lines)
    xyz = torch.rand(400, 3, generator=torch.Generator().manual_seed(2), dtype=torch.float64) * 2.6 - 1.3
    feats = torch.cat(grid.features(planes, lines, xyz), dim=-1)
    weight = torch.randn(5, feats.shape[1], generator=torch.Generator().manual_seed(3), dtype=torch.float64)
    summed = interp_volume(grid.dense(planes, lines), reso, xyz)
    projected = interp_volume(grid.dense(planes, lines, weight), reso, xyz)
    assert summed.shape == (400, 1) and projected.shape == (400, 5)
    torch.testing.assert_close(summed, feats.sum(dim=-1, keepdim=True), atol=1e-12, rtol=0)
    torch.testing.assert_close(projected, feats @ weight.T, atol=1e-12, rtol=0)
    with torch.no_grad():  # renders bake slab by slab
        rendered = interp_volume(grid.dense(planes, lines), reso, xyz)
        rendered_projected = interp_volume(grid.dense(planes, lines, weight), reso, xyz)
    torch.testing.assert_close(rendered, summed.detach(), atol=1e-12, rtol=0)
    torch.testing.assert_close(rendered_projected, projected.detach(), atol=1e-12, rtol=0)


@pytest.mark.parametrize("cls", [TensorVM, TensorCP])
def test_dense_table_rows_are_the_vertex_values_read_back_exactly(cls: type) -> None:
    reso = [4, 5, 3]
    grid = _grid64(cls, reso)
    planes, lines = list(grid.planes), list(grid.lines)
    table = grid.dense(planes, lines)
    idx = torch.stack(torch.meshgrid(*[torch.arange(r) for r in reso], indexing="ij"), dim=-1).reshape(-1, 3)
    xyz = idx.double() / (torch.tensor(reso, dtype=torch.float64) - 1) * 2 - 1
    rows = (idx[:, 2] * reso[1] + idx[:, 1]) * reso[0] + idx[:, 0]  # axis 0 fastest
    assert torch.equal(interp_volume(table, reso, xyz), table[rows])
    with torch.no_grad():
        torch.testing.assert_close(interp_volume(table, reso, xyz), table[rows], atol=1e-14, rtol=0)
    direct = torch.cat(grid.features(planes, lines, xyz), dim=-1).sum(dim=-1, keepdim=True)
    torch.testing.assert_close(table[rows], direct, atol=1e-12, rtol=0)


@pytest.mark.parametrize("cls", [TensorVM, TensorCP])
@pytest.mark.parametrize("channels", [1, 3])
def test_dense_table_gradients_reach_the_factors_as_the_factored_lookup_does(cls: type, channels: int) -> None:
    reso = [6, 5, 4]
    xyz = torch.rand(300, 3, generator=torch.Generator().manual_seed(5), dtype=torch.float64) * 2.2 - 1.1
    grads = []
    for dense in (True, False):
        grid = _grid64(cls, reso)
        planes, lines = list(grid.planes), list(grid.lines)
        width = sum(p.shape[0] for p in planes) if planes else lines[0].shape[0]
        weight = torch.linspace(-1, 1, channels * width, dtype=torch.float64).view(channels, width)
        weight = weight if channels > 1 else None
        if dense:
            out = interp_volume(grid.dense(planes, lines, weight), reso, xyz)
        else:
            feats = torch.cat(grid.features(planes, lines, xyz), dim=-1)
            out = feats.sum(dim=-1, keepdim=True) if weight is None else feats @ weight.T
        (out * torch.arange(1, channels + 1, dtype=torch.float64)).sum().backward()
        grads.append([p.grad for p in grid.parameters()])
    for a, b in zip(*grads, strict=True):
        assert torch.isfinite(a).all()
        torch.testing.assert_close(a, b, atol=1e-10, rtol=0)


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
    assert torch.autograd.gradcheck(lambda p, x: interp_plane(p, x[:, 0], x[:, 1], gather=True), (plane, uv))


def test_gather_lookup_of_no_points_is_empty_with_a_graph() -> None:
    plane = torch.randn(4, 3, 5, requires_grad=True)
    out = interp_plane(plane, torch.zeros(0), torch.zeros(0), gather=True)
    assert out.shape == (0, 4)
    out.sum().backward()
    assert torch.equal(plane.grad, torch.zeros_like(plane))


@pytest.mark.parametrize("reso", [[4, 3, 5], [1, 3, 2]])
def test_summed_vm_table_backward_passes_gradcheck(reso: list[int]) -> None:
    """Training's density table (``dense`` without a projection) has a hand-written backward: check it numerically."""
    grid = _grid64(TensorVM, reso)
    params = [p.detach().clone().requires_grad_() for p in (*grid.planes, *grid.lines)]

    def table(*factors: torch.Tensor) -> torch.Tensor:
        return grid.dense(list(factors[:3]), list(factors[3:]))

    assert torch.autograd.gradcheck(table, tuple(params))


@pytest.mark.parametrize("channels", [1, 4])
def test_interp_volume_is_grid_samples_trilinear_lookup(channels: int) -> None:
    """The 8-corner gather reads a [Z·Y·X, D] table exactly as ``grid_sample`` reads the [D, Z, Y, X] volume
    (align_corners=True, border clamping), inside the box and outside it."""
    reso = [5, 4, 3]
    g = torch.Generator().manual_seed(6)
    table = torch.randn(reso[0] * reso[1] * reso[2], channels, generator=g, dtype=torch.float64)
    xyz = torch.rand(200, 3, generator=g, dtype=torch.float64) * 2.6 - 1.3
    volume = table.T.reshape(1, channels, reso[2], reso[1], reso[0])
    expected = (
        torch.nn.functional.grid_sample(
            volume, xyz.view(1, -1, 1, 1, 3), mode="bilinear", align_corners=True, padding_mode="border"
        )
        .view(channels, -1)
        .T
    )
    torch.testing.assert_close(interp_volume(table, reso, xyz), expected, atol=1e-12, rtol=0)
