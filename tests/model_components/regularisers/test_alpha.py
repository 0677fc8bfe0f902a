"""ZeroRF's alpha term: zero where the opacity is the alpha, a gradient that pulls the opacity to the alpha, ZeroRF's
four-channel weighting, and built only where the scene's images carry alpha."""

from __future__ import annotations

import pytest
import torch

from fourierf_plugin.data.scene_effects import SceneEffects
from fourierf_plugin.model_components.regularisers.alpha import (
    TARGET_ALPHA,
    ZERORF_ALPHA_WEIGHT,
    Alpha,
    alpha_mse,
)
from fourierf_plugin.model_components.regularisers.base import Regulariser
from fourierf_plugin.utils.errors import UserError
from tests.model_components.regularisers.settings import options


def _zerorf(weight: float = ZERORF_ALPHA_WEIGHT) -> object:
    return options(alpha_weight=weight)


def test_the_term_is_zero_where_the_opacity_is_the_alpha() -> None:
    alpha = torch.tensor([0.0, 0.25, 1.0, 1.0], dtype=torch.float64)
    assert float(alpha_mse(alpha.clone(), alpha)) == 0.0
    acc = torch.tensor([0.5, 0.25, 1.0, 0.0], dtype=torch.float64)
    assert float(alpha_mse(acc, alpha)) == pytest.approx((0.25 + 0.0 + 0.0 + 1.0) / 4, rel=1e-12)


def test_its_gradient_pulls_the_opacity_to_the_alpha() -> None:
    """Opacity above the alpha (fog over a background pixel) gets a positive gradient, so a descent step lowers
    it; opacity below the alpha (a hole in the object) a negative one; opacity at the alpha none."""
    alpha = torch.tensor([0.0, 1.0, 0.5])
    acc = torch.tensor([0.3, 0.6, 0.5], requires_grad=True)
    alpha_mse(acc, alpha).backward()
    assert acc.grad is not None
    assert float(acc.grad[0]) > 0 and float(acc.grad[1]) < 0 and float(acc.grad[2]) == 0.0
    torch.testing.assert_close(acc.grad, 2 * (acc.detach() - alpha) / 3)


def test_no_rays_give_zero_with_a_graph() -> None:
    acc = torch.zeros(0, requires_grad=True)
    value = alpha_mse(acc, torch.zeros(0))
    value.backward()
    assert float(value.detach()) == 0.0 and acc.grad is not None


def test_the_weight_is_zerorfs_four_channel_mse() -> None:
    """ZeroRF's pixel loss on an RGBA target: one MSE over colour and opacity as four channels; here the RGB MSE plus
    the weighted alpha term, the same loss up to the factor 3/4."""
    g = torch.Generator().manual_seed(0)
    rgb, target_rgb = torch.rand(64, 3, generator=g, dtype=torch.float64), torch.rand(64, 3, generator=g)
    acc, alpha = torch.rand(64, generator=g, dtype=torch.float64), torch.rand(64, generator=g)
    rendered = torch.cat([rgb, acc[:, None]], dim=-1)
    target = torch.cat([target_rgb, alpha[:, None]], dim=-1).double()
    zerorf = torch.nn.functional.mse_loss(rendered, target)
    here = torch.nn.functional.mse_loss(rgb, target_rgb.double()) + ZERORF_ALPHA_WEIGHT * alpha_mse(acc, alpha)
    torch.testing.assert_close(zerorf, 0.75 * here)


def test_the_loss_is_the_weighted_term_of_the_target_alpha_handed_in() -> None:
    regulariser = Alpha(0.5)
    acc, alpha = torch.tensor([0.2, 0.9]), torch.tensor([0.0, 1.0])
    loss = regulariser.loss({"accumulation": acc, TARGET_ALPHA: alpha})
    assert loss is not None
    torch.testing.assert_close(loss, 0.5 * alpha_mse(acc, alpha))
    assert regulariser.loss({"accumulation": acc}) is None, "no target alpha: no term"
    assert type(regulariser).ray_term is Regulariser.ray_term and regulariser.unseen is None, "a loss term only"


@pytest.mark.parametrize("background", ["white", "black", "random"])
def test_it_is_on_wherever_the_background_is_known(background: str) -> None:
    built = Alpha.from_model(_zerorf(), SceneEffects(background=background), 100)  # type: ignore[arg-type]
    assert built == Alpha(ZERORF_ALPHA_WEIGHT)


def test_it_is_off_for_photos_and_at_weight_zero() -> None:
    assert Alpha.from_model(_zerorf(), SceneEffects(background="none"), 100) is None
    assert Alpha.from_model(_zerorf(0.0), SceneEffects(background="white"), 100) is None


@pytest.mark.parametrize("weight", [-0.1, float("nan")])
def test_a_bad_weight_is_one_clear_error(weight: float) -> None:
    with pytest.raises(UserError, match=r"--pipeline\.model\.alpha-weight"):
        Alpha.from_model(_zerorf(weight), SceneEffects(), 100)
