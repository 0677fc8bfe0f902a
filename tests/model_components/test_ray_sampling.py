"""Ray–box slab test, TensoRF's fixed-step marcher (spec 3.3, 7.5) and the two samplers built on them.

``box_samples`` (euclidean rays) and ``ndc_samples`` (NDC rays) must give points o + t d, flag the samples inside
the box, scale NDC deltas by |d| (NDC directions are not unit), hand unit view directions to the colour, and jitter
only when given a generator (renders are deterministic, training draws from the model's own generator).
"""

from __future__ import annotations

import math

import pytest
import torch
from hypothesis import given, settings
from hypothesis import strategies as st

from fourierf_plugin.model_components.ray_sampling import (
    box_samples,
    ndc_samples,
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


# -- the two samplers -----------------------------------------------------------------------------------------------


def _box_rays() -> tuple[torch.Tensor, torch.Tensor]:
    """A hit through the centre, an oblique hit, a ray starting inside and a miss (unit directions)."""
    o = torch.tensor([[-3.0, 0.0, 0.0], [-2.0, -1.5, -3.0], [0.2, -0.3, 0.5], [-3.0, 2.0, 0.0]])
    d = torch.nn.functional.normalize(torch.tensor([[1.0, 0.0, 0.0], [1.0, 0.7, 1.3], [0.3, 0.4, -1.0], [1.0, 0, 0]]))
    return o, d


def _ndc_rays(n: int = 16) -> tuple[torch.Tensor, torch.Tensor]:
    """NDC-like rays: origins on the z = -1 face, directions with d_z = 2 and |d| > 1 (not unit)."""
    g = torch.Generator().manual_seed(0)
    origins = torch.cat([(torch.rand(n, 2, generator=g) - 0.5) * 1.6, -torch.ones(n, 1)], dim=-1)
    directions = torch.cat([(torch.rand(n, 2, generator=g) - 0.5) * 1.5, torch.full((n, 1), 2.0)], dim=-1)
    return origins, directions


def _check_points_and_directions(samples, origins: torch.Tensor, directions: torch.Tensor) -> None:
    """points = o + t d; the view directions are the unit ray directions."""
    expected = origins.unsqueeze(1) + samples.t.unsqueeze(-1) * directions.unsqueeze(1)
    torch.testing.assert_close(samples.points, expected)
    unit = directions / directions.norm(dim=-1, keepdim=True)
    torch.testing.assert_close(samples.view_directions, unit)
    torch.testing.assert_close(samples.view_directions.norm(dim=-1), torch.ones(origins.shape[0]))


def test_box_samples_without_a_generator_sit_on_the_step_grid_from_the_entry() -> None:
    o, d = _box_rays()
    step = 0.1
    samples = box_samples(o, d, BOX, near=0.5, far=6.0, step=step, max_samples=1000)
    start, t_exit = ray_box_span(o, d, BOX, 0.5, 6.0)
    longest = float(((t_exit - start) / step).max())
    assert samples.shape == (4, math.ceil(longest) + 1), "as many samples as the longest ray needs"
    torch.testing.assert_close(samples.t, step_samples(start, step, samples.shape[1]))
    torch.testing.assert_close(samples.deltas, sample_deltas(samples.t))
    assert torch.equal(samples.inside, samples.t < t_exit.unsqueeze(-1))
    assert not bool(samples.inside[3].any()), "a miss has no sample inside the box"
    inner = samples.points[samples.inside]
    assert float(inner.abs().max()) <= 1.0 + 1e-5, "the samples flagged inside lie in the box"
    _check_points_and_directions(samples, o, d)
    again = box_samples(o, d, BOX, 0.5, 6.0, step, 1000)
    assert torch.equal(again.t, samples.t), "no generator, no jitter"


def test_box_samples_are_capped_at_max_samples() -> None:
    o, d = _box_rays()
    assert box_samples(o, d, BOX, 0.5, 6.0, 0.1, 7).shape == (4, 7)
    misses = box_samples(o[3:], d[3:], BOX, 0.5, 6.0, 0.1, 100)
    assert misses.shape == (1, 1) and not bool(misses.inside.any())


def test_box_samples_jitter_each_ray_by_one_fraction_of_a_step_with_a_generator() -> None:
    o, d = _box_rays()
    step = 0.1
    grid = box_samples(o, d, BOX, 0.5, 6.0, step, 1000)
    torch.manual_seed(123)
    global_next = torch.rand(1)
    torch.manual_seed(123)
    jittered = box_samples(o, d, BOX, 0.5, 6.0, step, 1000, torch.Generator().manual_seed(0))
    assert torch.equal(torch.rand(1), global_next), "the jitter draws from the given generator only"
    shift = jittered.t - grid.t
    torch.testing.assert_close(shift, shift[:, :1].expand_as(shift), atol=1e-5, rtol=0)  # one shift per ray
    assert bool((shift >= -1e-6).all() and (shift < step).all())
    assert float(shift[:, 0].std()) > 0, "each ray draws its own shift"
    torch.testing.assert_close(jittered.deltas[:, :-1], torch.full((4, grid.shape[1] - 1), step), atol=1e-5, rtol=0)
    _, t_exit = ray_box_span(o, d, BOX, 0.5, 6.0)
    assert torch.equal(jittered.inside, jittered.t < t_exit.unsqueeze(-1))
    _check_points_and_directions(jittered, o, d)
    same = box_samples(o, d, BOX, 0.5, 6.0, step, 1000, torch.Generator().manual_seed(0))
    assert torch.equal(same.t, jittered.t), "the same seed gives the same jitter"


def test_ndc_samples_without_a_generator_are_evenly_spaced_with_deltas_scaled_by_the_direction_length() -> None:
    o, d = _ndc_rays()
    samples = ndc_samples(o, d, BOX, near=0.0, far=1.0, num_samples=9)
    assert samples.shape == (16, 9)
    torch.testing.assert_close(samples.t, torch.linspace(0.0, 1.0, 9).expand(16, 9))
    length = d.norm(dim=-1, keepdim=True)
    torch.testing.assert_close(samples.deltas[:, :-1], (0.125 * length).expand(16, 8))
    assert bool((samples.deltas[:, -1] == 0).all())
    _check_points_and_directions(samples, o, d)
    assert torch.equal(ndc_samples(o, d, BOX, 0.0, 1.0, 9).t, samples.t), "no generator, no jitter"


def test_ndc_samples_jitter_each_sample_within_its_bin_with_a_generator() -> None:
    o, d = _ndc_rays()
    n = 8
    samples = ndc_samples(o, d, BOX, 0.0, 1.0, n, torch.Generator().manual_seed(0))
    jitter = samples.t - torch.linspace(0.0, 1.0, n)
    assert bool((jitter >= 0).all() and (jitter < 1 / n).all())
    assert float(jitter.std(dim=1).min()) > 0, "every sample draws its own jitter"
    assert bool((samples.t[:, 1:] > samples.t[:, :-1]).all()), "jittered samples stay ordered"
    torch.testing.assert_close(samples.deltas, sample_deltas(samples.t) * d.norm(dim=-1, keepdim=True))
    _check_points_and_directions(samples, o, d)


def test_ndc_samples_flag_the_points_inside_the_box() -> None:
    """A ray leaving the box sideways: its samples are inside exactly while |x| <= 1."""
    o = torch.tensor([[0.0, 0.0, -1.0], [0.85, 0.0, -1.0]])
    d = torch.tensor([[0.0, 0.0, 2.0], [1.0, 0.0, 2.0]])
    samples = ndc_samples(o, d, BOX, 0.0, 1.0, 11)
    assert bool(samples.inside[0].all())
    assert samples.inside[1].tolist() == [bool(x <= 1.0) for x in samples.points[1, :, 0].tolist()]
    assert samples.inside[1].tolist() == [True, True] + [False] * 9
