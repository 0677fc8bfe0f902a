"""Floaters-No-More: the factor clamp(t², 0, 1), and the step it acts from."""

from __future__ import annotations

import torch

from fourierf_plugin.data.scene_effects import SceneEffects
from fourierf_plugin.model_components.regularisers.floaters import FloatersNoMore, floaters_scale
from tests.model_components.regularisers.settings import options


def test_floaters_scale_is_clamped_t_squared() -> None:
    t = torch.tensor([0.0, 0.5, 1.0, 2.0, 6.0])
    torch.testing.assert_close(floaters_scale(t), torch.tensor([0.0, 0.25, 1.0, 1.0, 1.0]))


def test_it_is_off_unless_asked_for_and_acts_from_its_fraction_of_the_run() -> None:
    assert FloatersNoMore.from_model(options(), SceneEffects(), 300) is None
    late = FloatersNoMore.from_model(
        options(floaters_gradient_scaling=True, floaters_gradient_scaling_from=0.5), SceneEffects(), 300
    )
    assert late == FloatersNoMore(150)
    assert [late.scales_gradients_at(s) for s in (0, 149, 150, 300)] == [False, False, True, True]
    t = torch.tensor([[0.25, 3.0]])
    assert torch.equal(late.gradient_scale(t), floaters_scale(t))
