"""The TensoRF factorisations and their reference lookups (spec 3.1, 7.8: align_corners=True everywhere).

The reference lookups (``grid_sample``) return the stored values at vertices, averages at midpoints and the border
outside; VM/CP features are products of the given (filtered) factors with the documented layout; gradients reach
every factor; resizing (upsample, crop, replace) keeps the function and makes fresh parameters. The gather lookups
and dense tables that replace these in the fast path are compared with them in ``tests/accel``.
"""

from __future__ import annotations

import itertools

import pytest
import torch
from torch import nn

from fourierf_plugin.field_components.tensor_grids import (
    GRID_SAMPLE,
    MAT_MODES,
    VEC_MODES,
    TensorCP,
    TensorVM,
    interp_lines,
    interp_plane,
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
    times the neighbouring difference.
    """
    length = 128
    line = torch.randn(4, length, generator=_gen())
    coord64 = torch.tensor([_vertex_coord(i, length) for i in range(length)], dtype=torch.float64)
    torch.testing.assert_close(interp_lines(line.double(), coord64), line.T.double(), atol=1e-12, rtol=0)
    out = interp_lines(line, coord64.float())
    max_step = float((line[:, 1:] - line[:, :-1]).abs().max())
    bound = 8 * length * torch.finfo(torch.float32).eps * max_step
    assert float((out - line.T).abs().max()) <= bound


def test_interp_lines_midway_is_average() -> None:
    line = torch.randn(3, 6, generator=_gen())
    mids = torch.tensor([(_vertex_coord(i, 6) + _vertex_coord(i + 1, 6)) / 2 for i in range(5)])
    expected = 0.5 * (line[:, :-1] + line[:, 1:])
    torch.testing.assert_close(interp_lines(line, mids), expected.T, atol=1e-6, rtol=0)


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


def test_interp_plane_clamps_outside_range() -> None:
    """Points outside [-1, 1]² read the border (``padding_mode="border"``): the nearest edge's interpolation."""
    plane = torch.randn(2, 5, 7, generator=_gen(4))
    u = torch.tensor([-3.0, 2.5, 0.3, 0.3, -1.7])
    v = torch.tensor([0.2, -0.4, -2.0, 1.5, 9.0])
    torch.testing.assert_close(interp_plane(plane, u, v), interp_plane(plane, u.clamp(-1, 1), v.clamp(-1, 1)))
    corner = interp_plane(plane, torch.tensor([5.0]), torch.tensor([-5.0]))[0]
    torch.testing.assert_close(corner, plane[:, 0, -1])


def test_grid_sample_lookup_is_the_reference_interpolation() -> None:
    plane, line = torch.randn(3, 4, 6, generator=_gen(1)), torch.randn(3, 5, generator=_gen(2))
    u, v = _rand_points(40)[:, :2].T
    assert torch.equal(GRID_SAMPLE.plane(plane, u, v), interp_plane(plane, u, v))
    assert torch.equal(GRID_SAMPLE.line(line, v), interp_lines(line, v))


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
