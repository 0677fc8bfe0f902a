"""Geometry metrics: Chamfer distance, mesh surface samples and connected components."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh

from fourierf_plugin.synthetic import SceneSpec, Sphere, sample_surface
from fourierf_plugin.utils.geometry import chamfer_distance, component_sizes, count_components, mesh_surface_points


def _grid(n: int = 6) -> np.ndarray:
    axis = np.arange(n, dtype=np.float64)
    return np.stack(np.meshgrid(axis, axis, axis, indexing="ij"), axis=-1).reshape(-1, 3)


def test_chamfer_of_a_set_with_itself_is_zero() -> None:
    points = np.random.default_rng(0).normal(size=(500, 3))
    result = chamfer_distance(points, points)
    assert result["chamfer"] == 0.0 and result["chamfer_p90"] == 0.0
    assert result["n_a"] == result["n_b"] == 500


def test_chamfer_of_a_shifted_copy_is_the_shift() -> None:
    grid = _grid()  # unit spacing: a shift of 0.1 keeps every nearest neighbour the shifted twin
    shift = np.array([0.06, 0.0, 0.08])
    result = chamfer_distance(grid + shift, grid)
    for key in ("chamfer", "chamfer_p90", "a_to_b_mean", "b_to_a_mean", "a_to_b_p90", "a_to_b_max"):
        assert result[key] == pytest.approx(0.1)


def test_chamfer_directions_separate_floaters_from_holes() -> None:
    grid = _grid()
    with_floater = np.concatenate([grid, [[2.5, 2.5, 20.0]]])  # one far-away extra point in a
    result = chamfer_distance(with_floater, grid)
    assert result["b_to_a_mean"] == 0.0  # nothing of b is missed
    assert result["a_to_b_max"] == pytest.approx(np.hypot(np.hypot(0.5, 0.5), 15.0))
    assert result["a_to_b_mean"] == pytest.approx(result["a_to_b_max"] / len(with_floater))
    assert result["chamfer"] == pytest.approx(0.5 * result["a_to_b_mean"])
    assert result["a_to_b_p90"] == 0.0  # the percentile ignores the lone outlier


def test_chamfer_against_the_true_surface_of_a_sphere_is_small_and_grows_with_error() -> None:
    spec = SceneSpec((Sphere((0, 0, 0), 1.0, (1, 0, 0)),))
    truth = sample_surface(spec, 4000, seed=0)
    mesh = trimesh.creation.icosphere(subdivisions=4, radius=1.0)
    good = chamfer_distance(mesh_surface_points(mesh, 4000, seed=1), truth)
    big = trimesh.creation.icosphere(subdivisions=4, radius=1.1)
    worse = chamfer_distance(mesh_surface_points(big, 4000, seed=1), truth)
    assert good["chamfer"] < 0.03
    assert worse["chamfer"] > good["chamfer"] + 0.05


@pytest.mark.parametrize(("a", "b"), [(np.zeros((0, 3)), np.zeros((3, 3))), (np.zeros((3, 2)), np.zeros((3, 3)))])
def test_chamfer_rejects_bad_point_sets(a: np.ndarray, b: np.ndarray) -> None:
    with pytest.raises(ValueError, match=r"\[N, 3\]|empty"):
        chamfer_distance(a, b)


def test_mesh_surface_points_lie_on_the_icosphere_and_follow_the_seed() -> None:
    mesh = trimesh.creation.icosphere(subdivisions=3, radius=2.0)
    points = mesh_surface_points(mesh, 3000, seed=7)
    assert points.shape == (3000, 3)
    radii = np.linalg.norm(points, axis=1)
    assert radii.max() <= 2.0 + 1e-9 and radii.min() > 2.0 * 0.99  # on the flat faces: within their sagitta
    np.testing.assert_array_equal(points, mesh_surface_points(mesh, 3000, seed=7))
    assert not np.array_equal(points, mesh_surface_points(mesh, 3000, seed=8))
    # Every octant gets its share: the samples cover the whole sphere, not one patch.
    octants = np.unique((points > 0) @ np.array([1, 2, 4]), return_counts=True)[1]
    assert len(octants) == 8 and octants.min() > 3000 / 8 * 0.8


def test_mesh_surface_points_refuses_an_empty_mesh() -> None:
    with pytest.raises(ValueError, match="no surface"):
        mesh_surface_points(trimesh.Trimesh(), 10)


def test_count_components_counts_pieces_and_drops_small_ones() -> None:
    big = trimesh.creation.icosphere(subdivisions=2)  # 320 faces
    small = trimesh.creation.box(extents=(0.2, 0.2, 0.2))  # 12 faces
    small.apply_translation([3.0, 0.0, 0.0])
    triangle = trimesh.Trimesh(vertices=[[5, 0, 0], [6, 0, 0], [5, 1, 0]], faces=[[0, 1, 2]])
    scene = trimesh.util.concatenate([big, small, triangle])
    assert count_components(scene) == 3
    assert count_components(scene, min_faces=2) == 2
    assert count_components(scene, min_faces=13) == 1
    assert component_sizes(scene).tolist() == [320, 12, 1]
    assert count_components(trimesh.Trimesh()) == 0
