"""RegNeRF's depth smoothness: closed forms on planes, steps, constants and no patches; what the regulariser is
built from and scores."""

from __future__ import annotations

import pytest
import torch

from fourierf_plugin.data.scene_effects import SceneEffects
from fourierf_plugin.model_components.regularisers.base import UnseenViews
from fourierf_plugin.model_components.regularisers.depth_smoothness import DepthSmoothness, depth_smoothness
from tests.model_components.regularisers.settings import options


def _ramp_plane(c: int, h: int, w: int, a: float, b: float) -> torch.Tensor:
    rows = torch.arange(h, dtype=torch.float64)[:, None]
    cols = torch.arange(w, dtype=torch.float64)[None, :]
    return (a * rows + b * cols).expand(c, h, w).clone()


@pytest.mark.parametrize(("a", "b"), [(0.3, -0.2), (1.0, 0.0), (0.0, 2.5)])
def test_depth_smoothness_of_a_tilted_plane(a: float, b: float) -> None:
    """Patches of a planar depth a·row + b·col: every vertical difference is a, every horizontal one b."""
    patches = _ramp_plane(5, 8, 8, a, b)
    assert float(depth_smoothness(patches)) == pytest.approx(a * a + b * b, rel=1e-12, abs=1e-15)


def test_depth_smoothness_of_constant_and_of_no_patches_is_zero() -> None:
    assert float(depth_smoothness(torch.full((3, 4, 4), 0.6))) == 0.0
    empty = torch.zeros(0, 8, 8, requires_grad=True)
    value = depth_smoothness(empty)
    value.backward()
    assert float(value.detach()) == 0.0 and empty.grad is not None


def test_depth_smoothness_penalises_a_step_by_its_height() -> None:
    """One 8×8 patch with a step of height h between columns 3 and 4: one horizontal jump per row of 7 differences."""
    patch = torch.zeros(1, 8, 8, dtype=torch.float64)
    patch[:, :, 4:] = 0.5
    assert float(depth_smoothness(patch)) == pytest.approx(0.25 / 7)


def test_it_is_off_at_weight_0_and_renders_its_patches_otherwise() -> None:
    assert DepthSmoothness.from_model(options(), SceneEffects(), 100) is None
    on = DepthSmoothness.from_model(options(depth_smoothness_weight=0.1), SceneEffects(), 100)
    assert on == DepthSmoothness(0.1, UnseenViews(4, 8)) and on.unseen.rays == 256


def test_its_unseen_loss_is_the_weighted_term_on_the_rendered_patches() -> None:
    regulariser = DepthSmoothness(0.5, UnseenViews(2, 8))
    depth = _ramp_plane(2, 8, 8, 0.3, -0.2).reshape(-1)
    assert float(regulariser.unseen_loss({"depth": depth})) == pytest.approx(0.5 * (0.09 + 0.04), rel=1e-12)
