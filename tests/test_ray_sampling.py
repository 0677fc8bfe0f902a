"""Ray–box slab test and TensoRF's fixed-step marcher (spec 3.3, 7.5)."""

from __future__ import annotations

import pytest
import torch
from hypothesis import given, settings
from hypothesis import strategies as st

from fourierf_plugin.model_components.ray_sampling import (
    ray_aabb_intersect,
    ray_box_span,
    sample_deltas,
    step_samples,
)

BOX = torch.tensor([[-1.0, -1.0, -1.0], [1.0, 1.0, 1.0]])


def _rays(origins: list[list[float]], directions: list[list[float]]) -> tuple[torch.Tensor, torch.Tensor]:
    return torch.tensor(origins), torch.tensor(directions)


def test_hit_through_the_centre() -> None:
    o, d = _rays([[-3.0, 0.0, 0.0], [0.0, 5.0, 0.0]], [[1.0, 0.0, 0.0], [0.0, -2.0, 0.0]])
    t_min, t_max = ray_aabb_intersect(o, d, BOX)
    assert t_min.tolist() == pytest.approx([2.0, 2.0], abs=1e-5)
    assert t_max.tolist() == pytest.approx([4.0, 3.0], abs=1e-5)


def test_oblique_hit_entry_and_exit_on_the_box() -> None:
    o = torch.tensor([[-2.0, -1.5, -3.0]])
    d = torch.nn.functional.normalize(torch.tensor([[1.0, 0.7, 1.3]]), dim=-1)
    t_min, t_max = ray_aabb_intersect(o, d, BOX)
    assert float(t_max) > float(t_min)
    for t in (t_min, t_max):
        p = o + t[:, None] * d
        assert float(p.abs().max()) == pytest.approx(1.0, abs=1e-5)  # on the surface
        assert float(p.abs().max()) <= 1.0 + 1e-5


def test_miss() -> None:
    o, d = _rays([[-3.0, 2.0, 0.0], [-3.0, 0.0, 0.0]], [[1.0, 0.0, 0.0], [-1.0, 0.0, 0.0]])
    t_min, t_max = ray_aabb_intersect(o, d, BOX)
    assert bool(t_max[0] <= t_min[0])  # passes above the box
    assert float(t_max[1]) < 0  # the box lies behind the ray


def test_grazing_an_edge_is_a_degenerate_hit() -> None:
    """A ray that touches only the edge x = 1, y = 1 enters and leaves at the same t (t_max == t_min: a miss)."""
    o = torch.tensor([[0.0, 2.0, 0.0]])
    d = torch.nn.functional.normalize(torch.tensor([[1.0, -1.0, 0.0]]), dim=-1)
    t_min, t_max = ray_aabb_intersect(o, d, BOX)
    assert torch.isfinite(t_min).all() and torch.isfinite(t_max).all()
    assert float(t_min) == pytest.approx(2**0.5, abs=1e-5)
    assert float(t_max) == pytest.approx(float(t_min), abs=1e-5)
    assert bool(t_max <= t_min + 1e-6)


@pytest.mark.parametrize("face", [-1.0, 1.0])
def test_ray_lying_in_a_face_plane_is_finite(face: float) -> None:
    """Axis-parallel rays on a face (0 · ∞ territory without the 1e-6 guard) give finite, NaN-free parameters."""
    o = torch.tensor([[-3.0, face, 0.0]])
    d = torch.tensor([[1.0, 0.0, 0.0]])
    t_min, t_max = ray_aabb_intersect(o, d, BOX)
    assert torch.isfinite(t_min).all() and torch.isfinite(t_max).all()
    assert float(t_min) == pytest.approx(2.0, abs=1e-5)


def test_origin_inside_the_box() -> None:
    o = torch.tensor([[0.2, -0.3, 0.5]])
    d = torch.nn.functional.normalize(torch.tensor([[0.3, 0.4, -1.0]]), dim=-1)
    t_min, t_max = ray_aabb_intersect(o, d, BOX)
    assert float(t_min) < 0 < float(t_max)
    exit_point = o + t_max[:, None] * d
    assert float(exit_point.abs().max()) == pytest.approx(1.0, abs=1e-5)


def test_axis_parallel_rays_are_finite() -> None:
    o = torch.tensor([[0.5, 0.5, -4.0], [0.5, 3.0, -4.0], [0.0, 0.0, 0.0], [0.3, 0.3, 5.0]])
    d = torch.tensor([[0.0, 0.0, 1.0], [0.0, 0.0, 1.0], [-0.0, 1.0, -0.0], [0.0, -0.0, -1.0]])
    t_min, t_max = ray_aabb_intersect(o, d, BOX)
    assert torch.isfinite(t_min).all() and torch.isfinite(t_max).all()
    assert t_min[0].item() == pytest.approx(3.0, abs=1e-5) and t_max[0].item() == pytest.approx(5.0, abs=1e-5)
    assert bool(t_max[1] <= t_min[1])  # parallel and outside the y slab: a miss
    assert t_min[2].item() == pytest.approx(-1.0, abs=1e-5) and t_max[2].item() == pytest.approx(1.0, abs=1e-5)
    assert t_min[3].item() == pytest.approx(4.0, abs=1e-5) and t_max[3].item() == pytest.approx(6.0, abs=1e-5)


@settings(max_examples=60, deadline=None)
@given(
    st.lists(st.floats(-3, 3), min_size=3, max_size=3),
    st.lists(st.floats(-1, 1), min_size=3, max_size=3),
)
def test_slab_interval_is_inside_the_box(origin: list[float], direction: list[float]) -> None:
    o, d = torch.tensor([origin]), torch.tensor([direction])
    t_min, t_max = ray_aabb_intersect(o, d, BOX)
    assert not torch.isnan(t_min).any() and not torch.isnan(t_max).any()
    if float(d.abs().max()) > 1e-3 and float(t_max - t_min) > 1e-3:
        mid = o + 0.5 * (t_min + t_max)[:, None] * d
        assert float(mid.abs().max()) <= 1.0 + 1e-4


def test_ray_box_span_clamps_start_to_near_far() -> None:
    o = torch.tensor([[-3.0, 0.0, 0.0], [0.0, 0.0, 0.0], [-30.0, 0.0, 0.0]])
    d = torch.tensor([[1.0, 0.0, 0.0]] * 3)
    start, t_exit = ray_box_span(o, d, BOX, near=0.5, far=6.0)
    # box entry 2.0 stays; inside origin (entry -1) is clamped up to near; entry 29 is clamped down to far.
    assert start.tolist() == pytest.approx([2.0, 0.5, 6.0], abs=1e-5)
    assert t_exit.tolist() == pytest.approx([4.0, 1.0, 31.0], abs=1e-5)


def test_step_samples_spacing_and_jitter() -> None:
    start = torch.tensor([0.5, 2.0])
    t = step_samples(start, 0.25, 6)
    assert t.shape == (2, 6)
    expected = start[:, None] + 0.25 * torch.arange(6.0)[None]
    assert torch.equal(t, expected)
    torch.testing.assert_close(t[:, 1:] - t[:, :-1], torch.full((2, 5), 0.25))
    u = torch.tensor([0.3, 0.9])
    tj = step_samples(start, 0.25, 6, jitter=u)
    torch.testing.assert_close(tj - t, (0.25 * u)[:, None].expand(2, 6), atol=1e-6, rtol=0)
    torch.testing.assert_close(tj[:, 1:] - tj[:, :-1], torch.full((2, 5), 0.25), atol=1e-6, rtol=0)


def test_step_samples_keeps_dtype() -> None:
    t = step_samples(torch.zeros(3, dtype=torch.float64), 0.1, 4)
    assert t.dtype == torch.float64


def test_sample_deltas_last_is_zero() -> None:
    t = torch.tensor([[0.0, 0.1, 0.3, 0.6], [1.0, 2.0, 4.0, 8.0]])
    deltas = sample_deltas(t)
    assert deltas.shape == t.shape
    torch.testing.assert_close(deltas, torch.tensor([[0.1, 0.2, 0.3, 0.0], [1.0, 2.0, 4.0, 0.0]]))
    assert (deltas[:, -1] == 0).all()
    single = sample_deltas(torch.tensor([[3.0]]))
    assert single.tolist() == [[0.0]]
