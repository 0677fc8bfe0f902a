"""Marching rays through the field (``model_components.marching``): which samples the density and colour functions
see, and what comes back.

Directly: ``densities`` queries exactly the samples inside the box and in occupied cells; ``densities_until_opaque``
stops querying a ray once its optical depth passes -log T_stop (checked segment by segment, scaled by the distance
scale) and otherwise agrees with ``densities``; ``shade`` evaluates colour only above the weight threshold, passes
view directions only when asked, and its gradient scale reaches colour gradients only.

Through the model (early ray termination in renders): the render is unchanged to ~T_stop, samples behind an opaque
wall are never queried, the segment length does not change the render, and training marches every sample.
"""

from __future__ import annotations

import math

import pytest
import torch

from fourierf_plugin.accel import AccelConfig
from fourierf_plugin.model_components.marching import densities, densities_until_opaque, shade
from fourierf_plugin.model_components.occupancy import OccupancyGrid
from fourierf_plugin.model_components.ray_sampling import RaySamples, sample_deltas
from fourierf_plugin.models.fourierf import FourieRFModel
from tests.helpers import rays_through_the_slab, slab_model

BOX = torch.tensor([[-1.0] * 3, [1.0] * 3])


class Recorder:
    """A density or colour function that records the points it was asked about."""

    def __init__(self, fn) -> None:
        self.fn = fn
        self.calls: list[torch.Tensor] = []
        self.directions: list[torch.Tensor | None] = []

    def __call__(self, xyz: torch.Tensor, directions: torch.Tensor | None = None) -> torch.Tensor:
        self.calls.append(xyz.detach().clone())
        self.directions.append(directions)
        return self.fn(xyz) if directions is None else self.fn(xyz, directions)

    @property
    def queried(self) -> int:
        return sum(c.shape[0] for c in self.calls)


# -- direct tests on hand-made samples --------------------------------------------------------------------------------

RAY_SIGMA = torch.tensor([0.0, 10.0, 0.5])
"""σ of each of the three rays of ``ray_samples``: empty, an opaque wall, a thin medium."""


def ray_samples(num_samples: int = 12) -> RaySamples:
    """Three parallel rays along z at x = -0.1, 0, 0.1, unit steps in t, points spread through z in [-0.9, 0.9]."""
    t = torch.arange(num_samples, dtype=torch.float32).expand(3, num_samples)
    z = torch.linspace(-0.9, 0.9, num_samples)
    points = torch.stack(
        [
            torch.tensor([-0.1, 0.0, 0.1]).view(3, 1).expand(3, num_samples),
            torch.zeros(3, num_samples),
            z.expand(3, num_samples),
        ],
        dim=-1,
    )
    inside = torch.ones(3, num_samples, dtype=torch.bool)
    directions = torch.tensor([[0.0, 0.0, 1.0]]).expand(3, 3)
    return RaySamples(t, sample_deltas(t), points, inside, directions)


def ray_sigma(xyz: torch.Tensor) -> torch.Tensor:
    """σ by the ray a point lies on (its x coordinate), see ``RAY_SIGMA``."""
    ray = ((xyz[:, 0] + 0.1) / 0.1).round().long()
    return RAY_SIGMA[ray]


def lower_half_occupancy() -> OccupancyGrid:
    """Occupied cells: z < 0 of the box (2³ cells whose z = -1 vertices are on)."""
    vertices = torch.zeros(3, 3, 3, dtype=torch.bool)
    vertices[:, :, 0] = True
    grid = OccupancyGrid()
    grid.set(vertices, BOX)
    return grid


def test_densities_query_every_sample_inside_the_box_and_zero_the_rest() -> None:
    samples = ray_samples()
    samples.inside[0, 5:] = False
    samples.inside[2, :2] = False
    density = Recorder(ray_sigma)
    sigma = densities(density, samples, OccupancyGrid())
    assert density.queried == int(samples.inside.sum())
    expected = torch.where(samples.inside, RAY_SIGMA.view(3, 1).expand(3, 12), torch.zeros(()))
    assert torch.equal(sigma, expected)


def test_densities_skip_unoccupied_cells() -> None:
    samples = ray_samples()
    density = Recorder(ray_sigma)
    sigma = densities(density, samples, lower_half_occupancy())
    occupied = samples.points[..., 2] < 0
    assert density.queried == int(occupied.sum()) == 18
    assert bool((torch.cat(density.calls)[:, 2] < 0).all())
    assert torch.equal(sigma, torch.where(occupied, RAY_SIGMA.view(3, 1).expand(3, 12), torch.zeros(())))


def test_densities_of_no_rays_query_nothing() -> None:
    samples = ray_samples()
    empty = RaySamples(samples.t[:0], samples.deltas[:0], samples.points[:0], samples.inside[:0], samples.t[:0, :3])
    density = Recorder(ray_sigma)
    assert densities(density, empty, OccupancyGrid()).shape == (0, 12)
    assert densities_until_opaque(density, empty, OccupancyGrid(), 1.0, 1e-2, 4).shape == (0, 12)
    assert density.queried == 0


def test_marching_until_opaque_stops_each_ray_after_the_segment_that_makes_it_opaque() -> None:
    """T_stop = 1e-2 (optical depth 4.6), segments of 4 unit steps: the wall (σ 10, depth 40 after one segment)
    stops after 4 samples; the thin medium (σ 0.5: depth 2, 4, 6) needs all three segments; the empty ray all."""
    samples = ray_samples()
    density = Recorder(ray_sigma)
    sigma = densities_until_opaque(density, samples, OccupancyGrid(), 1.0, 1e-2, 4)
    queried = torch.cat(density.calls)
    per_ray = [int(((queried[:, 0] - x).abs() < 1e-6).sum()) for x in (-0.1, 0.0, 0.1)]
    assert per_ray == [12, 4, 12]
    full = densities(ray_sigma, samples, OccupancyGrid())
    assert torch.equal(sigma[[0, 2]], full[[0, 2]])
    assert torch.equal(sigma[1, :4], full[1, :4]) and bool((sigma[1, 4:] == 0).all())


def test_marching_until_opaque_scales_the_optical_depth_by_the_distance_scale() -> None:
    """With distance scale 3 the thin medium reaches depth 6 > 4.6 in its first segment and stops there too."""
    density = Recorder(ray_sigma)
    densities_until_opaque(density, ray_samples(), OccupancyGrid(), 3.0, 1e-2, 4)
    queried = torch.cat(density.calls)
    per_ray = [int(((queried[:, 0] - x).abs() < 1e-6).sum()) for x in (-0.1, 0.0, 0.1)]
    assert per_ray == [12, 4, 4]


@pytest.mark.parametrize("segment", [1, 5, 100])
def test_marching_until_opaque_with_an_unreachable_stop_equals_densities(segment: int) -> None:
    """A stop no ray reaches (T_stop = 1e-300: depth 690) leaves nothing out, occupancy and box included."""
    samples = ray_samples()
    samples.inside[1, -3:] = False
    occupancy = lower_half_occupancy()
    density = Recorder(ray_sigma)
    sigma = densities_until_opaque(density, samples, occupancy, 1.0, 1e-300, segment)
    assert torch.equal(sigma, densities(ray_sigma, samples, occupancy))
    assert density.queried == int((samples.inside & (samples.points[..., 2] < 0)).sum())
    assert len(density.calls) <= math.ceil(12 / segment)


def shading_setup() -> tuple[RaySamples, torch.Tensor, torch.Tensor]:
    """Two rays of three samples; ray 0 has two samples above the 1e-4 threshold, ray 1 none; a learnable tint."""
    samples = ray_samples(3)
    samples = RaySamples(samples.t[:2], samples.deltas[:2], samples.points[:2] + 1.0, samples.inside[:2],
                         torch.tensor([[0.6, 0.0, 0.8], [0.0, 1.0, 0.0]]))  # fmt: skip
    weights = torch.tensor([[0.5, 1e-5, 0.2], [1e-5, 5e-5, 1e-5]], requires_grad=True)
    tint = torch.tensor([1.0, 2.0, 3.0], requires_grad=True)
    return samples, weights, tint


def test_shade_evaluates_colour_only_above_the_threshold() -> None:
    samples, weights, tint = shading_setup()
    color = Recorder(lambda xyz: xyz * tint)
    rgb = shade(color, samples, weights, 1e-4, view_dependent=False)
    assert color.queried == 2 and color.directions == [None]
    torch.testing.assert_close(color.calls[0], samples.points[0, [0, 2]])
    points = samples.points
    expected_ray0 = 0.5 * points[0, 0] * tint + 0.2 * points[0, 2] * tint
    torch.testing.assert_close(rgb, torch.stack([expected_ray0, torch.zeros(3)]))
    assert bool((rgb[1] == 0).all()), "samples under the threshold count as black"


def test_shade_with_nothing_above_the_threshold_is_black_without_asking_for_colour() -> None:
    samples, weights, _ = shading_setup()
    color = Recorder(lambda xyz: xyz)
    rgb = shade(color, samples, weights, 0.6, view_dependent=True)
    assert torch.equal(rgb, torch.zeros(2, 3)) and color.queried == 0


def test_shade_passes_each_samples_view_direction_when_view_dependent() -> None:
    samples, weights, _ = shading_setup()
    with torch.no_grad():
        weights[1, 1] = 0.3  # now ray 1 has a shaded sample too
    color = Recorder(lambda xyz, dirs: dirs)
    rgb = shade(color, samples, weights, 1e-4, view_dependent=True)
    (directions,) = color.directions
    assert directions is not None
    torch.testing.assert_close(directions, samples.view_directions[[0, 0, 1]])
    torch.testing.assert_close(rgb, torch.stack([0.7 * samples.view_directions[0], 0.3 * samples.view_directions[1]]))


def test_shade_gradient_scale_scales_colour_gradients_only() -> None:
    """Forward unchanged; d rgb / d colour parameters scaled per sample; d rgb / d weights (= colour) unscaled."""
    samples, weights, tint = shading_setup()
    scale = torch.tensor([[0.25, 7.0, 0.5], [3.0, 3.0, 3.0]])
    results = {}
    for name, gradient_scale in (("plain", None), ("scaled", scale)):
        weights.grad = tint.grad = None
        rgb = shade(lambda xyz, _: xyz * tint, samples, weights, 1e-4, False, gradient_scale)
        rgb.sum().backward()
        results[name] = (rgb.detach(), weights.grad.clone(), tint.grad.clone())
    (rgb_plain, w_plain, tint_plain), (rgb_scaled, w_scaled, tint_scaled) = results["plain"], results["scaled"]
    assert torch.equal(rgb_plain, rgb_scaled)
    assert torch.equal(w_plain, w_scaled)
    points = samples.points
    torch.testing.assert_close(tint_plain, 0.5 * points[0, 0] + 0.2 * points[0, 2])
    torch.testing.assert_close(tint_scaled, 0.25 * 0.5 * points[0, 0] + 0.5 * 0.2 * points[0, 2])


# -- early ray termination through the model --------------------------------------------------------------------------


def slab(slab_density: float, **accel) -> FourieRFModel:
    """``slab_model`` with these accel settings (early_stop_transmittance, early_stop_segment)."""
    return slab_model(slab_density, accel=AccelConfig(**accel))


def count_density_queries(model: FourieRFModel) -> list[int]:
    counts: list[int] = []
    density = model.field.density

    def counted(xyz: torch.Tensor) -> torch.Tensor:
        counts.append(xyz.shape[0])
        return density(xyz)

    model.field.density = counted  # type: ignore[method-assign]
    return counts


@pytest.mark.parametrize("slab_density", [0.0, 0.05, 50.0])
def test_early_termination_matches_the_full_march(slab_density: float) -> None:
    origins, directions = rays_through_the_slab()
    full = slab(slab_density, early_stop_transmittance=0.0).render_rays(origins, directions, step=10)
    early = slab(slab_density).render_rays(origins, directions, step=10)
    for key in ("rgb", "accumulation"):
        torch.testing.assert_close(early[key], full[key], atol=2e-4, rtol=0)
    assert torch.isfinite(early["depth"]).all()


def test_an_opaque_wall_stops_the_queries_behind_it() -> None:
    origins, directions = rays_through_the_slab()
    full, early = slab(50.0, early_stop_transmittance=0.0), slab(50.0, early_stop_segment=4)
    full_counts, early_counts = count_density_queries(full), count_density_queries(early)
    full.render_rays(origins, directions, step=10)
    out = early.render_rays(origins, directions, step=10)
    assert bool((out["accumulation"] > 1 - 1e-4).all())  # the wall is opaque
    assert sum(early_counts) < 0.7 * sum(full_counts)  # the back third of the box and more are skipped


@pytest.mark.parametrize("segment", [1, 7, 10_000])
def test_segment_length_does_not_change_the_render(segment: int) -> None:
    origins, directions = rays_through_the_slab()
    reference = slab(0.05).render_rays(origins, directions, step=10)
    out = slab(0.05, early_stop_segment=segment).render_rays(origins, directions, step=10)
    for key in ("rgb", "accumulation", "depth"):
        torch.testing.assert_close(out[key], reference[key], atol=2e-4, rtol=0)


def test_training_marches_every_sample() -> None:
    """Gradients need every sample: the training forward ignores the render's early stop."""
    origins, directions = rays_through_the_slab(8)
    model = slab(50.0, early_stop_segment=4)
    counts = count_density_queries(model)
    model.prepare(0)
    model.train()(origins, directions)
    assert len(counts) == 1  # one query in training
    model.render_rays(origins, directions, step=0)
    assert model.training, "render_rays restores the mode it found"
    assert len(counts) > 2  # several segments in the render
    assert counts[0] > sum(counts[1:])  # and training queried more samples than the early-stopped render


def test_segments_skip_unoccupied_cells_like_the_full_march() -> None:
    """With an occupancy grid the segments query only live samples in occupied cells, and render what the full
    march (which checks every sample against the grid up front) renders."""
    origins, directions = rays_through_the_slab()
    models = [slab(0.05, early_stop_transmittance=0.0), slab(0.05, early_stop_segment=16)]
    counts = []
    for model in models:
        with torch.no_grad():
            model.prepare(10)
            model._update_occupancy(shrink=False, step=10)
        assert model.occupancy.active and not bool(model.occupancy.cells.all())
        counts.append(count_density_queries(model))
    full, early = (m.render_rays(origins, directions, step=10) for m in models)
    for key in ("rgb", "accumulation", "depth"):
        torch.testing.assert_close(early[key], full[key], atol=2e-4, rtol=0)
    assert sum(counts[1]) == sum(counts[0])  # the slab is not opaque: the same occupied samples, in segments


def test_an_occupancy_update_says_how_much_of_the_grid_it_kept(capsys: pytest.CaptureFixture[str]) -> None:
    """What an update prunes is never sampled again, so the log says what it kept (a run pruned while still dark
    shows it there)."""
    model = slab(0.05)
    with torch.no_grad():
        model.prepare(10)
        model._update_occupancy(shrink=False, step=10)
    kept = model.occupancy.cells.float().mean().item()
    assert 0 < kept < 1
    assert f"occupancy update after step 10: {kept:.0%} of the grid kept" in capsys.readouterr().out
