"""Occupancy (alpha) grid: dilation, cell OR, occupied box, AABB shrink and lookups (spec 3.4, 7.3, 7.8)."""

from __future__ import annotations

import itertools

import pytest
import torch

from fourierf_plugin.model_components.occupancy import (
    OccupancyGrid,
    cells_from_vertices,
    occupancy_from_alpha,
    occupied_aabb,
    shrink_bounds,
    vertex_grid,
)

AABB = torch.tensor([[-1.0, 0.0, 2.0], [1.0, 3.0, 3.0]])
RESO = [5, 7, 3]


def _units() -> torch.Tensor:
    return (AABB[1] - AABB[0]) / (torch.tensor(RESO, dtype=torch.float32) - 1)


def _vertex_pos(i: int, j: int, k: int) -> torch.Tensor:
    return AABB[0] + torch.tensor([i, j, k], dtype=torch.float32) * _units()


def test_vertex_grid_corners_and_spacing() -> None:
    grid = vertex_grid(AABB, RESO)
    assert grid.shape == (5, 7, 3, 3)
    assert torch.equal(grid[0, 0, 0], AABB[0])
    torch.testing.assert_close(grid[-1, -1, -1], AABB[1])
    torch.testing.assert_close(grid[2, 3, 1], _vertex_pos(2, 3, 1))


def test_occupancy_from_alpha_dilates_a_single_voxel_to_a_block() -> None:
    alpha = torch.zeros(7, 8, 9)
    alpha[3, 4, 5] = 0.5
    mask = occupancy_from_alpha(alpha, 1e-4)
    assert mask.dtype == torch.bool
    expected = torch.zeros(7, 8, 9, dtype=torch.bool)
    expected[2:5, 3:6, 4:7] = True
    assert torch.equal(mask, expected)
    # At a corner the block is clipped, not wrapped.
    corner = torch.zeros(4, 4, 4)
    corner[0, 0, 0] = 1.0
    assert int(occupancy_from_alpha(corner, 1e-4).sum()) == 8


def test_occupancy_threshold() -> None:
    alpha = torch.full((3, 3, 3), 5e-5)
    assert not occupancy_from_alpha(alpha, 1e-4).any()
    alpha[1, 1, 1] = 1e-4
    assert occupancy_from_alpha(alpha, 1e-4).all()  # ≥ threshold, dilated over the whole 3³ grid


def test_cells_are_or_of_their_eight_corners() -> None:
    gen = torch.Generator().manual_seed(0)
    vertices = torch.rand(5, 6, 4, generator=gen) > 0.85
    cells = cells_from_vertices(vertices)
    assert cells.shape == (4, 5, 3)
    for i, j, k in itertools.product(range(4), range(5), range(3)):
        assert bool(cells[i, j, k]) == bool(vertices[i : i + 2, j : j + 2, k : k + 2].any())


def test_occupied_aabb_empty_is_none() -> None:
    assert occupied_aabb(torch.zeros(*RESO, dtype=torch.bool), AABB) is None


def test_occupied_aabb_known_mask() -> None:
    vertices = torch.zeros(*RESO, dtype=torch.bool)
    vertices[1, 2, 0] = True
    vertices[3, 5, 1] = True
    box = occupied_aabb(vertices, AABB)
    assert box is not None and box.shape == (2, 3)
    torch.testing.assert_close(box[0], _vertex_pos(1, 2, 0))
    torch.testing.assert_close(box[1], _vertex_pos(3, 5, 1))
    full = occupied_aabb(torch.ones(*RESO, dtype=torch.bool), AABB)
    torch.testing.assert_close(full, AABB)


def test_shrink_bounds_indices_and_box_on_vertices() -> None:
    new = torch.stack([_vertex_pos(1, 2, 0) + 0.01, _vertex_pos(3, 5, 1) - 0.01])
    lo, hi, box = shrink_bounds(new, AABB, RESO)
    assert lo == [1, 2, 0] and hi == [4, 6, 2]  # [round(lo), round(hi) + 1)
    torch.testing.assert_close(box[0], _vertex_pos(1, 2, 0))
    torch.testing.assert_close(box[1], _vertex_pos(3, 5, 1))
    # Every box corner is a vertex of the old grid: the crop [lo, hi) spans exactly the new box.
    for corner, idx in ((box[0], lo), (box[1], [h - 1 for h in hi])):
        torch.testing.assert_close(corner, _vertex_pos(*idx))


def test_shrink_bounds_of_the_whole_box_is_identity() -> None:
    lo, hi, box = shrink_bounds(AABB.clone(), AABB, RESO)
    assert lo == [0, 0, 0] and hi == RESO
    torch.testing.assert_close(box, AABB)


def test_shrink_bounds_clamps_to_the_grid() -> None:
    bigger = torch.stack([AABB[0] - 5.0, AABB[1] + 5.0])
    lo, hi, box = shrink_bounds(bigger, AABB, RESO)
    assert lo == [0, 0, 0] and hi == RESO
    torch.testing.assert_close(box, AABB)


@pytest.mark.parametrize("index", [0, 2, 4])
def test_shrink_bounds_keeps_two_vertices_for_a_flat_box(index: int) -> None:
    """A one-vertex-thick occupied region (also on the far face) still gives ≥ 2 vertices inside the grid."""
    vertices = torch.zeros(*RESO, dtype=torch.bool)
    vertices[index, 1:4, 1] = True
    box = occupied_aabb(vertices, AABB)
    lo, hi, new_box = shrink_bounds(box, AABB, RESO)
    for axis in range(3):
        assert lo[axis] >= 0 and hi[axis] <= RESO[axis] and hi[axis] - lo[axis] >= 2
    assert lo[0] <= index < hi[0]
    assert (new_box[0] >= AABB[0] - 1e-6).all() and (new_box[1] <= AABB[1] + 1e-6).all()
    torch.testing.assert_close(new_box[0], _vertex_pos(*lo))
    torch.testing.assert_close(new_box[1], _vertex_pos(*[h - 1 for h in hi]))


# --------------------------------------------------------------------------------------------------- the grid
def test_query_before_set_is_all_true() -> None:
    grid = OccupancyGrid()
    assert not grid.active
    xyz = torch.tensor([[100.0, 0.0, 0.0], [0.0, 0.0, 0.0]])
    assert grid.query(xyz).tolist() == [True, True]
    assert grid.query(torch.zeros(0, 3)).shape == (0,)


def test_query_after_set() -> None:
    vertices = torch.zeros(*RESO, dtype=torch.bool)
    vertices[1, 1, 1] = True
    grid = OccupancyGrid()
    grid.set(vertices, AABB)
    assert grid.active and grid.cells.shape == (4, 6, 2)
    units = _units()
    on = _vertex_pos(1, 1, 1)
    inside = torch.stack([on, on + 0.4 * units, on - 0.9 * units, on + torch.tensor([0.99, -0.99, 0.5]) * units])
    assert grid.query(inside).all()
    far_cells = torch.stack([_vertex_pos(3, 5, 0) + 0.5 * units, _vertex_pos(2, 2, 1) + 0.5 * units])
    assert not grid.query(far_cells).any()
    outside = torch.stack([AABB[0] - 0.01, AABB[1] + 0.01, on + torch.tensor([0.0, 0.0, 5.0])])
    assert not grid.query(outside).any()


def test_query_includes_the_box_faces() -> None:
    grid = OccupancyGrid()
    grid.set(torch.ones(*RESO, dtype=torch.bool), AABB)
    corners = torch.stack([AABB[0], AABB[1], torch.stack([AABB[1, 0], AABB[0, 1], AABB[1, 2]])])
    assert grid.query(corners).all()


def test_thin_slab_mask() -> None:
    """One layer of on vertices (x index 2) switches on the two cell layers that touch it, nothing else."""
    vertices = torch.zeros(*RESO, dtype=torch.bool)
    vertices[2] = True
    grid = OccupancyGrid()
    grid.set(vertices, AABB)
    assert grid.cells[1:3].all() and not grid.cells[0].any() and not grid.cells[3].any()
    units = _units()
    gen = torch.Generator().manual_seed(0)
    yz = AABB[0, 1:] + torch.rand(50, 2, generator=gen) * (AABB[1, 1:] - AABB[0, 1:])

    def at(x: float) -> torch.Tensor:
        return torch.cat([torch.full((50, 1), x), yz], dim=-1)

    x_slab = float(_vertex_pos(2, 0, 0)[0])
    assert grid.query(at(x_slab)).all()
    assert grid.query(at(x_slab - 0.9 * float(units[0]))).all()
    assert grid.query(at(x_slab + 0.9 * float(units[0]))).all()
    assert not grid.query(at(x_slab - 1.1 * float(units[0]))).any()
    assert not grid.query(at(x_slab + 1.1 * float(units[0]))).any()


def test_thin_slab_on_the_far_face() -> None:
    vertices = torch.zeros(*RESO, dtype=torch.bool)
    vertices[:, :, -1] = True
    grid = OccupancyGrid()
    grid.set(vertices, AABB)
    xyz = torch.tensor([[0.0, 1.5, 3.0], [0.0, 1.5, 2.6], [0.0, 1.5, 2.4]])
    assert grid.query(xyz).tolist() == [True, True, False]


def test_grid_state_travels_in_state_dict() -> None:
    grid = OccupancyGrid()
    vertices = torch.zeros(*RESO, dtype=torch.bool)
    vertices[1:3, 2:4, 1] = True
    grid.set(vertices, AABB)
    other = OccupancyGrid()
    other.cells = torch.zeros_like(grid.cells)  # shapes must match to load
    other.load_state_dict(grid.state_dict())
    xyz = vertex_grid(AABB, RESO).reshape(-1, 3)
    assert torch.equal(other.query(xyz), grid.query(xyz))
