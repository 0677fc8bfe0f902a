"""Early ray termination at evaluation: the render is unchanged to ~T_stop, and samples behind an opaque wall are
never queried."""

from __future__ import annotations

import pytest
import torch

from fourierf_plugin.data.dataparser_base import SceneDeclaration
from fourierf_plugin.fields.fourier_tensorf_field import FieldConfig
from fourierf_plugin.models.fourierf import FourieRFModel, FourieRFModelConfig
from tests.helpers import single_torch_thread  # noqa: F401 - autouse fixture

BLENDER = SceneDeclaration(
    background="white", ray_space="euclidean", bounded=True, view_dependent=False, occlusion_regularization=False
)


def slab_model(slab_density: float, **config) -> FourieRFModel:
    """A 16³ ReLU field with σ = ``slab_density`` for z in the middle third of the box, 0 elsewhere."""
    field = FieldConfig(
        n_voxels_init=16**3, density_components=(2, 2, 2), appearance_components=(3, 3, 3), appearance_dim=6,
        hidden_dim=16, density_activation="relu",
    )  # fmt: skip
    torch.manual_seed(0)  # the decoder's layers draw from the global generator
    model = FourieRFModelConfig(field=field, **config).setup(
        scene_box=torch.tensor([[-1.5] * 3, [1.5] * 3]), near=0.5, far=6.0, declaration=BLENDER, max_iters=10,
        generator=torch.Generator().manual_seed(0),
    )  # fmt: skip
    grid = model.field.density_grid
    with torch.no_grad():
        for p in [*grid.planes, *grid.lines]:
            p.zero_()
        grid.planes[0][0].fill_(1.0)  # the xy plane times the z line
        z = grid.lines[0].shape[1]
        grid.lines[0][0, z // 3 : 2 * z // 3] = slab_density
    model.field.invalidate()
    return model


def rays_through_the_slab(n: int = 64) -> tuple[torch.Tensor, torch.Tensor]:
    g = torch.Generator().manual_seed(1)
    origins = torch.cat([torch.rand(n, 2, generator=g) - 0.5, torch.full((n, 1), -3.0)], dim=-1)
    directions = torch.cat([(torch.rand(n, 2, generator=g) - 0.5) * 0.2, torch.ones(n, 1)], dim=-1)
    return origins, directions / directions.norm(dim=-1, keepdim=True)


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
