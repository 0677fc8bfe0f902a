"""InfoNeRF's ray entropy: 0 and log2 N bits, rays that hit nothing, hard rays; the regulariser's options and
terms."""

from __future__ import annotations

import pytest
import torch

from fourierf_plugin.data.scene_effects import SceneEffects
from fourierf_plugin.model_components.regularisers.base import TrainingRays, UnseenViews
from fourierf_plugin.model_components.regularisers.entropy import Entropy, ray_entropy
from fourierf_plugin.model_components.rendering import opacity_from_density
from tests.model_components.regularisers.settings import options


def test_ray_entropy_is_zero_for_one_opaque_sample_and_log2_n_for_an_even_ray() -> None:
    """Opacity in one sample: 0 bits; even over N samples: log2 N bits (α scaled alike: only the shape counts)."""
    alpha = torch.zeros(2, 16, dtype=torch.float64)
    alpha[0, 5] = 0.9
    alpha[1] = 0.2
    acc = torch.ones(2, dtype=torch.float64)
    assert float(ray_entropy(alpha[:1], acc[:1], 0.1)) == pytest.approx(0.0, abs=1e-8)
    assert float(ray_entropy(alpha[1:], acc[1:], 0.1)) == pytest.approx(4.0, rel=1e-8)
    assert float(ray_entropy(alpha, acc, 0.1)) == pytest.approx(2.0, rel=1e-8)  # a mean over both rays


def test_ray_entropy_leaves_out_rays_that_hit_nothing_and_divides_by_all() -> None:
    alpha = torch.full((4, 8), 0.01, dtype=torch.float64)
    acc = torch.tensor([0.5, 0.05, 0.1, 0.9], dtype=torch.float64)  # at the threshold counts as a miss
    assert float(ray_entropy(alpha, acc, 0.1)) == pytest.approx(2 * 3.0 / 4, rel=1e-8)


def test_ray_entropy_gradients_stay_finite_on_hard_rays() -> None:
    """Empty rays, one-hot rays, rays with a single zero-opacity sample beside opaque ones and no rays at all."""
    alpha = torch.zeros(4, 32)
    alpha[1, 3] = 1.0
    alpha[2, :31] = 1.0
    alpha[3] = torch.linspace(0.0, 1.0, 32)
    alpha.requires_grad_(True)
    acc = torch.tensor([0.0, 1.0, 1.0, 1.0])
    value = ray_entropy(alpha, acc, 0.1)
    value.backward()
    assert torch.isfinite(value) and alpha.grad is not None and bool(torch.isfinite(alpha.grad).all())
    assert bool((alpha.grad[0] == 0).all())  # a miss has no gradient
    empty = torch.zeros(0, 8, requires_grad=True)
    nothing = ray_entropy(empty, torch.zeros(0), 0.1)
    nothing.backward()
    assert float(nothing.detach()) == 0.0 and empty.grad is not None


def test_it_is_off_at_weight_0_and_renders_single_rays_from_unseen_poses() -> None:
    assert Entropy.from_model(options(), SceneEffects(), 100) is None
    on = Entropy.from_model(options(entropy_weight=0.001), SceneEffects(), 100)
    assert on == Entropy(0.001, 0.1, UnseenViews(1024, 1))
    only_training = Entropy.from_model(options(entropy_weight=0.001, entropy_unseen_rays=0), SceneEffects(), 100)
    assert only_training is not None and only_training.unseen is None


def test_its_terms_are_the_entropy_of_the_rays_opacity() -> None:
    generator = torch.Generator().manual_seed(2)
    sigma = torch.rand(5, 12, generator=generator, dtype=torch.float64)
    deltas = torch.full((5, 12), 0.01, dtype=torch.float64)
    acc = torch.tensor([0.0, 0.5, 0.9, 0.2, 0.05], dtype=torch.float64)
    rays = TrainingRays(sigma, deltas, deltas, sigma, acc, 0.0, 1.0, 25.0)
    regulariser = Entropy(0.5, 0.1, UnseenViews(4, 1))
    term = regulariser.ray_term(rays)
    assert torch.equal(term, ray_entropy(opacity_from_density(sigma, deltas, 25.0), acc, 0.1))
    assert torch.equal(regulariser.loss({"entropy": term}), 0.5 * term)
    assert torch.equal(regulariser.unseen_loss({"entropy": term}), 0.5 * term)
