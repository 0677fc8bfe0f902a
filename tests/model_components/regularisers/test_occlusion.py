"""FreeNeRF's occlusion term: the first M samples of each ray, on FreeNeRF's σ; built only where the scene asks for
it."""

from __future__ import annotations

import pytest
import torch

from fourierf_plugin.data.scene_effects import SceneEffects
from fourierf_plugin.model_components.regularisers.base import TrainingRays
from fourierf_plugin.model_components.regularisers.occlusion import Occlusion, occlusion_penalty
from tests.model_components.regularisers.settings import options


@pytest.mark.parametrize(("k", "m"), [(128, 20), (64, 10), (256, 40), (7, 1)])
def test_occlusion_penalty_sums_the_first_m_samples(k: int, m: int) -> None:
    sigma = torch.arange(3 * k, dtype=torch.float64).reshape(3, k) / k
    expected = sigma[:, :m].sum(dim=-1).mean() / k  # = mean over rays and all K samples of σ_k 1[k < M]
    torch.testing.assert_close(occlusion_penalty(sigma, 20 / 128, 1.0), expected)
    masked = sigma * (torch.arange(k) < m)
    torch.testing.assert_close(occlusion_penalty(sigma, 20 / 128, 1.0), masked.mean())


def test_occlusion_penalty_ignores_samples_past_m() -> None:
    sigma = torch.zeros(4, 128)
    sigma[:, 20:] = 100.0
    assert occlusion_penalty(sigma, 20 / 128, 1.0).item() == 0.0
    sigma[:, 19] = 128.0
    assert occlusion_penalty(sigma, 20 / 128, 1.0).item() == pytest.approx(1.0)


@pytest.mark.parametrize("distance_scale", [1.0, 2.5, 25.0])
def test_occlusion_penalty_is_on_freenerfs_sigma(distance_scale: float) -> None:
    """FreeNeRF composites 1 - exp(-σ_F δ), this pipeline 1 - exp(-distance_scale σ δ): the term is on σ_F, linear in
    the distance scale, so at the default 25 it is 25 times the term on the raw σ."""
    sigma = torch.rand(5, 128, generator=torch.Generator().manual_seed(3), dtype=torch.float64)
    raw = occlusion_penalty(sigma, 20 / 128, 1.0)
    torch.testing.assert_close(occlusion_penalty(sigma, 20 / 128, distance_scale), distance_scale * raw)
    empty = occlusion_penalty(torch.zeros(0, 128, requires_grad=True), 20 / 128, distance_scale)
    assert empty.item() == 0.0 and empty.requires_grad, "no rays: 0 with a graph, not NaN"


def test_it_is_built_where_the_scene_asks_for_it_and_its_weight_is_positive() -> None:
    asks = SceneEffects(occlusion_regularization=True)
    assert Occlusion.from_model(options(), asks, 100) == Occlusion(0.01, 20 / 128)
    assert Occlusion.from_model(options(), SceneEffects(), 100) is None
    assert Occlusion.from_model(options(occlusion_weight=0.0), asks, 100) is None


def test_its_term_is_the_penalty_at_the_renders_distance_scale() -> None:
    sigma = torch.rand(3, 64, generator=torch.Generator().manual_seed(0), dtype=torch.float64)
    rays = TrainingRays(sigma, sigma, sigma, sigma, sigma.sum(-1), 0.0, 1.0, 25.0)
    term = Occlusion(0.01, 20 / 128).ray_term(rays)
    assert torch.equal(term, occlusion_penalty(sigma, 20 / 128, 25.0))
