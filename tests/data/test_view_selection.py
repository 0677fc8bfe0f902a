"""Few-shot view selection: seeded k-means without duplicates, and validation of explicit ids."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from fourierf_plugin.data.view_selection import _nearest_distinct, explicit_views, kmeans_views
from fourierf_plugin.utils.errors import UserError


def _hemisphere(n: int, seed: int = 0) -> np.ndarray:
    rng = np.random.default_rng(seed)
    v = rng.normal(size=(n, 3))
    v[:, 2] = np.abs(v[:, 2])
    return 4.0 * v / np.linalg.norm(v, axis=1, keepdims=True)


def test_deterministic_for_a_seed() -> None:
    centers = _hemisphere(100)
    first = kmeans_views(centers, 4, seed=3)
    assert first == kmeans_views(centers, 4, seed=3)
    assert len(set(first)) == 4 and first == sorted(first)
    picks = {tuple(kmeans_views(centers, 6, seed=s)) for s in range(3)}
    assert all(len(set(p)) == 6 for p in picks)


def test_one_view_per_separated_blob() -> None:
    rng = np.random.default_rng(0)
    blobs = np.array([[0, 0, 0], [10, 0, 0], [0, 10, 0], [0, 0, 10]], dtype=float)
    centers = np.concatenate([b + 0.1 * rng.normal(size=(5, 3)) for b in blobs])  # blob k holds ids 5k..5k+4
    picked = kmeans_views(centers, 4, seed=0)
    assert sorted(i // 5 for i in picked) == [0, 1, 2, 3]


def test_shared_nearest_view_gives_distinct_views() -> None:
    # Both centres are nearest to view 0; the farther centre must take its nearest *untaken* view.
    points = np.array([[0.0, 0, 0], [-3, 0, 0], [5, 0, 0], [0, 9, 0]])
    centres = np.array([[-1.0, 0, 0], [1.5, 0, 0]])
    assert _nearest_distinct(points, centres) == [0, 2]  # not [0, 0], and not the closer-to-c0 view 1


def test_duplicated_cameras_never_repeat_a_view() -> None:
    # Two coincident camera pairs and 3 clusters: two cluster centres coincide, so they share a nearest view.
    centers = np.array([[1.0, 0, 0], [1.0, 0, 0], [0, 1.0, 0], [0, 1.0, 0]])
    for seed in range(5):
        picked = kmeans_views(centers, 3, seed=seed)
        assert len(set(picked)) == 3 and all(0 <= i < 4 for i in picked)


def test_n_equal_all_and_bad_n() -> None:
    centers = _hemisphere(7)
    assert kmeans_views(centers, 7) == list(range(7))
    with pytest.raises(ValueError):
        kmeans_views(centers, 8)
    with pytest.raises(ValueError):
        kmeans_views(centers, 0)


@settings(max_examples=25, deadline=None)
@given(n_points=st.integers(1, 30), data=st.data())
def test_any_cloud_gives_distinct_sorted_ids(n_points: int, data: st.DataObject) -> None:
    n = data.draw(st.integers(1, n_points))
    seed = data.draw(st.integers(0, 2**16))
    centers = np.random.default_rng(seed).integers(-3, 4, size=(n_points, 3)).astype(float)  # many duplicates
    picked = kmeans_views(centers, n, seed=seed, n_init=2)
    assert picked == sorted(set(picked)) and len(picked) == n
    assert all(0 <= i < n_points for i in picked)


def test_explicit_views_validation() -> None:
    assert explicit_views([27, 3, 99], 100, "transforms_train.json") == [27, 3, 99]
    with pytest.raises(UserError) as info:
        explicit_views([3, 100, -1], 100, "scene/transforms_train.json")
    assert "[100, -1]" in info.value.problem and "scene/transforms_train.json" in info.value.problem
    assert "0..99" in info.value.fix
    with pytest.raises(UserError, match=r"\[3\]"):
        explicit_views([3, 4, 3], 100, "transforms_train.json")
    with pytest.raises(UserError):
        explicit_views([], 100, "transforms_train.json")
