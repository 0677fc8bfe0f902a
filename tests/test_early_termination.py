"""Early ray termination at evaluation: the render is unchanged to ~T_stop, and samples behind an opaque wall are
never queried."""

from __future__ import annotations

import pytest
import torch

from fourierf_plugin.models.fourierf import FourieRFModel
from tests.helpers import (
    rays_through_the_slab,
    single_torch_thread,  # noqa: F401 - autouse fixture
    slab_model,
)


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
    full = slab_model(slab_density, eval_stop_transmittance=0.0).render_rays(origins, directions, step=10)
    early = slab_model(slab_density).render_rays(origins, directions, step=10)
    for key in ("rgb", "accumulation"):
        torch.testing.assert_close(early[key], full[key], atol=2e-4, rtol=0)
    assert torch.isfinite(early["depth"]).all()


def test_an_opaque_wall_stops_the_queries_behind_it() -> None:
    origins, directions = rays_through_the_slab()
    full, early = slab_model(50.0, eval_stop_transmittance=0.0), slab_model(50.0, eval_segment_samples=4)
    full_counts, early_counts = count_density_queries(full), count_density_queries(early)
    full.render_rays(origins, directions, step=10)
    out = early.render_rays(origins, directions, step=10)
    assert bool((out["accumulation"] > 1 - 1e-4).all())  # the wall is opaque
    assert sum(early_counts) < 0.7 * sum(full_counts)  # the back third of the box and more are skipped


@pytest.mark.parametrize("segment", [1, 7, 10_000])
def test_segment_length_does_not_change_the_render(segment: int) -> None:
    origins, directions = rays_through_the_slab()
    reference = slab_model(0.05).render_rays(origins, directions, step=10)
    out = slab_model(0.05, eval_segment_samples=segment).render_rays(origins, directions, step=10)
    for key in ("rgb", "accumulation", "depth"):
        torch.testing.assert_close(out[key], reference[key], atol=2e-4, rtol=0)


def test_training_marches_every_sample() -> None:
    """Gradients need every sample: the training forward ignores the evaluation stop."""
    origins, directions = rays_through_the_slab(8)
    model = slab_model(50.0, eval_segment_samples=4)
    counts = count_density_queries(model)
    model.prepare(0)
    model(origins, directions, training=True)
    model.eval()
    with torch.no_grad():
        model.render_rays(origins, directions, step=0)
    assert len(counts) > 2  # one query in training, several segments at evaluation
    assert counts[0] > sum(counts[1:])  # and training queried more samples than the early-stopped render


def test_segments_skip_unoccupied_cells_like_the_full_march() -> None:
    """With an occupancy grid the segments query only live samples in occupied cells, and render what the full
    march (which checks every sample against the grid up front) renders."""
    origins, directions = rays_through_the_slab()
    models = [slab_model(0.05, eval_stop_transmittance=0.0), slab_model(0.05, eval_segment_samples=16)]
    counts = []
    for model in models:
        with torch.no_grad():
            model.prepare(10)
            model._update_occupancy(shrink=False)
        assert model.occupancy.active and not bool(model.occupancy.cells.all())
        counts.append(count_density_queries(model))
    full, early = (m.render_rays(origins, directions, step=10) for m in models)
    for key in ("rgb", "accumulation", "depth"):
        torch.testing.assert_close(early[key], full[key], atol=2e-4, rtol=0)
    assert sum(counts[1]) == sum(counts[0])  # the slab is not opaque: the same occupied samples, in segments
