"""Dense vertex tables (``accel.dense_tables``) read the same field as the factored reference lookup.

A VM or CP grid is a trilinear lookup of its vertex values (bilinear plane x linear line = trilinear on the
products). Here ``interp_volume`` of ``dense_table`` equals ``grid.features`` (the reference ``grid_sample``
lookup), summed (density) or projected (the appearance basis), inside the box and clamped outside, with and
without gradients (the slab-by-slab render builder); the table's rows are the vertex values; gradients reach the
factors as through the factored lookup; and the summed VM table's hand-written backward passes gradcheck.
"""

from __future__ import annotations

import pytest
import torch

from fourierf_plugin.accel.dense_tables import _SummedVMTable, dense_table
from fourierf_plugin.accel.lookups import interp_volume
from fourierf_plugin.field_components.tensor_grids import TensorCP, TensorVM

GRIDS = [TensorVM, TensorCP]


def _grid64(cls: type, reso: list[int]) -> TensorVM | TensorCP:
    comps = (3, 4, 2) if cls is TensorVM else (4, 4, 4)
    return cls(reso, comps, 0.7, torch.Generator().manual_seed(4)).double()


def _points(n: int, seed: int, spread: float) -> torch.Tensor:
    return torch.rand(n, 3, generator=torch.Generator().manual_seed(seed), dtype=torch.float64) * 2 * spread - spread


@pytest.mark.parametrize("cls", GRIDS)
@pytest.mark.parametrize("reso", [[5, 6, 7], [2, 9, 3], [1, 4, 6]])
def test_dense_table_lookup_is_the_factored_lookup(cls: type, reso: list[int]) -> None:
    """The baked table reads the same field, inside the box and clamped outside, summed (density) or projected
    (the appearance basis); renders build it without gradients (slab by slab) to the same values."""
    grid = _grid64(cls, reso)
    planes, lines = list(grid.planes), list(grid.lines)
    xyz = _points(400, 2, 1.3)
    feats = torch.cat(grid.features(planes, lines, xyz), dim=-1)
    weight = torch.randn(5, feats.shape[1], generator=torch.Generator().manual_seed(3), dtype=torch.float64)
    summed = interp_volume(dense_table(grid, planes, lines), reso, xyz)
    projected = interp_volume(dense_table(grid, planes, lines, weight), reso, xyz)
    assert summed.shape == (400, 1) and projected.shape == (400, 5)
    torch.testing.assert_close(summed, feats.sum(dim=-1, keepdim=True), atol=1e-12, rtol=0)
    torch.testing.assert_close(projected, feats @ weight.T, atol=1e-12, rtol=0)
    with torch.no_grad():  # renders bake slab by slab
        rendered = interp_volume(dense_table(grid, planes, lines), reso, xyz)
        rendered_projected = interp_volume(dense_table(grid, planes, lines, weight), reso, xyz)
    torch.testing.assert_close(rendered, summed.detach(), atol=1e-12, rtol=0)
    torch.testing.assert_close(rendered_projected, projected.detach(), atol=1e-12, rtol=0)


@pytest.mark.parametrize("cls", GRIDS)
def test_dense_table_rows_are_the_vertex_values_read_back_exactly(cls: type) -> None:
    reso = [4, 5, 3]
    grid = _grid64(cls, reso)
    planes, lines = list(grid.planes), list(grid.lines)
    table = dense_table(grid, planes, lines)
    assert table.shape == (4 * 5 * 3, 1)
    idx = torch.stack(torch.meshgrid(*[torch.arange(r) for r in reso], indexing="ij"), dim=-1).reshape(-1, 3)
    xyz = idx.double() / (torch.tensor(reso, dtype=torch.float64) - 1) * 2 - 1
    rows = (idx[:, 2] * reso[1] + idx[:, 1]) * reso[0] + idx[:, 0]  # axis 0 fastest
    assert torch.equal(interp_volume(table, reso, xyz), table[rows])
    direct = torch.cat(grid.features(planes, lines, xyz), dim=-1).sum(dim=-1, keepdim=True)
    torch.testing.assert_close(table[rows], direct, atol=1e-12, rtol=0)


@pytest.mark.parametrize("cls", GRIDS)
@pytest.mark.parametrize("channels", [1, 3])
def test_dense_table_gradients_reach_the_factors_as_the_factored_lookup_does(cls: type, channels: int) -> None:
    reso = [6, 5, 4]
    xyz = _points(300, 5, 1.1)
    grads = []
    for dense in (True, False):
        grid = _grid64(cls, reso)
        planes, lines = list(grid.planes), list(grid.lines)
        width = sum(p.shape[0] for p in planes) if planes else lines[0].shape[0]
        weight = torch.linspace(-1, 1, channels * width, dtype=torch.float64).view(channels, width)
        weight = weight if channels > 1 else None
        if dense:
            out = interp_volume(dense_table(grid, planes, lines, weight), reso, xyz)
        else:
            feats = torch.cat(grid.features(planes, lines, xyz), dim=-1)
            out = feats.sum(dim=-1, keepdim=True) if weight is None else feats @ weight.T
        (out * torch.arange(1, channels + 1, dtype=torch.float64)).sum().backward()
        grads.append([p.grad for p in grid.parameters()])
    for a, b in zip(*grads, strict=True):
        assert torch.isfinite(a).all()
        torch.testing.assert_close(a, b, atol=1e-10, rtol=0)


def test_float32_tables_match_the_factored_lookup_to_rounding() -> None:
    grid = TensorVM([7, 5, 6], (4, 4, 4), 0.5, torch.Generator().manual_seed(1))
    planes, lines = list(grid.planes), list(grid.lines)
    xyz = _points(200, 8, 1.0).float()
    weight = torch.randn(6, 12, generator=torch.Generator().manual_seed(2))
    feats = torch.cat(grid.features(planes, lines, xyz), dim=-1)
    with torch.no_grad():
        table = dense_table(grid, planes, lines, weight)
    assert table.dtype == torch.float32
    torch.testing.assert_close(interp_volume(table, grid.resolution, xyz), (feats @ weight.T).detach())


@pytest.mark.parametrize("reso", [[4, 3, 5], [1, 3, 2]])
def test_summed_vm_table_backward_passes_gradcheck(reso: list[int]) -> None:
    """Training's density table (``dense_table`` without a projection) has a hand-written backward."""
    grid = _grid64(TensorVM, reso)
    params = tuple(p.detach().clone().requires_grad_() for p in (*grid.planes, *grid.lines))
    assert torch.autograd.gradcheck(_SummedVMTable.apply, params)
    torch.testing.assert_close(_SummedVMTable.apply(*params), dense_table(grid, list(grid.planes), list(grid.lines)))
