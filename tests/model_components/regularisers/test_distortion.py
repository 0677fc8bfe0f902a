"""mip-NeRF 360's distortion loss: its pairwise definition, closed forms, no rays; the regulariser's term in
normalised ray distance."""

from __future__ import annotations

import pytest
import torch

from fourierf_plugin.data.scene_effects import SceneEffects
from fourierf_plugin.model_components.regularisers.base import TrainingRays
from fourierf_plugin.model_components.regularisers.distortion import Distortion, distortion
from tests.model_components.regularisers.settings import options


def _distortion_by_pairs(weights: torch.Tensor, s: torch.Tensor) -> torch.Tensor:
    """mip-NeRF 360's definition term by term, O(N²): every pair of intervals, then each interval with itself."""
    lengths = torch.cat([s.diff(dim=-1), torch.zeros_like(s[..., :1])], dim=-1)
    mids = s + 0.5 * lengths
    pairs = (weights[:, :, None] * weights[:, None, :] * (mids[:, :, None] - mids[:, None, :]).abs()).sum(dim=(1, 2))
    return (pairs + (weights.square() * lengths).sum(dim=-1) / 3.0).mean()


def test_distortion_matches_its_pairwise_definition() -> None:
    generator = torch.Generator().manual_seed(3)
    s = torch.rand(6, 40, generator=generator, dtype=torch.float64).sort(dim=-1).values
    weights = torch.rand(6, 40, generator=generator, dtype=torch.float64)
    weights = weights / weights.sum(dim=-1, keepdim=True) * torch.rand(6, 1, generator=generator, dtype=torch.float64)
    assert float(distortion(weights, s)) == pytest.approx(float(_distortion_by_pairs(weights, s)), rel=1e-12)


def test_distortion_of_one_interval_is_its_own_term_and_of_two_surfaces_their_distance() -> None:
    """All weight in one interval of length d: w² d / 3. Half at each of two intervals D apart (d → 0): D / 2."""
    s = torch.linspace(0.0, 1.0, 11, dtype=torch.float64)[None]
    one = torch.zeros(1, 11, dtype=torch.float64)
    one[0, 4] = 0.8
    assert float(distortion(one, s)) == pytest.approx(0.64 * 0.1 / 3.0, rel=1e-12)
    two = torch.zeros(1, 11, dtype=torch.float64)
    two[0, 1] = two[0, 7] = 0.5
    assert float(distortion(two, s)) == pytest.approx(2 * 0.25 * 0.6 + 2 * 0.25 * 0.1 / 3.0, rel=1e-12)
    assert float(distortion(two, s)) > float(distortion(one, s))  # doubled geometry costs more than one surface


def test_distortion_of_no_rays_is_zero_and_its_gradient_finite() -> None:
    empty = torch.zeros(0, 8, requires_grad=True)
    value = distortion(empty, torch.zeros(0, 8))
    value.backward()
    assert float(value.detach()) == 0.0 and empty.grad is not None
    weights = torch.full((4, 16), 1.0 / 16, requires_grad=True)
    distortion(weights, torch.linspace(0.0, 1.0, 16).expand(4, 16)).backward()
    assert weights.grad is not None and bool(torch.isfinite(weights.grad).all())


def test_it_is_off_at_weight_0_and_takes_its_weight_otherwise() -> None:
    assert Distortion.from_model(options(), SceneEffects(), 100) is None
    assert Distortion.from_model(options(distortion_weight=0.01), SceneEffects(), 100) == Distortion(0.01)


def test_its_term_is_on_ray_distance_normalised_from_near_to_far() -> None:
    t = torch.linspace(2.0, 6.0, 11, dtype=torch.float64)[None]
    weights = torch.zeros(1, 11, dtype=torch.float64)
    weights[0, 1] = weights[0, 7] = 0.5
    rays = TrainingRays(weights, t, t, weights, weights.sum(-1), 2.0, 6.0, 25.0)
    regulariser = Distortion(0.1)
    term = regulariser.ray_term(rays)
    assert float(term) == pytest.approx(float(distortion(weights, (t - 2.0) / 4.0)), rel=1e-12)
    assert float(regulariser.loss({"distortion": term})) == pytest.approx(0.1 * float(term), rel=1e-12)
    assert regulariser.loss({}) is None
