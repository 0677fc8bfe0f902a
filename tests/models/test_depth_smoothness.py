"""RegNeRF's depth smoothness on unseen-view patches, through pipelines built the way ``fourierf-train`` builds them.

Off by default (no extra rays rendered, no random numbers drawn); on, it adds one finite term whose gradient reaches
the density grids; the patches are NDC rays on a forward-facing scene; a patch larger than the images is one clear
error naming the flag.
"""

from __future__ import annotations

from pathlib import Path

import pytest
import torch

from fourierf_plugin.model_components.regularisers import DepthSmoothness, Regulariser
from fourierf_plugin.models.fourierf import FourieRFModel
from fourierf_plugin.utils.errors import UserError
from tests.helpers import TINY_SCENE
from tests.models.test_scene_effects import (
    assert_gradients_reach_the_density_grids,
    assert_loss_is_the_sum_of_its_terms,
    assert_same_training_batches,
    pipeline_for,
)

ON = ("--pipeline.model.depth-smoothness-weight", "0.1", "--pipeline.model.depth-smoothness-patch-size", "4")


def smoothness(model: FourieRFModel) -> Regulariser:
    """The model's DepthSmoothness regulariser."""
    (found,) = [r for r in model.regularisers if isinstance(r, DepthSmoothness)]
    return found


def test_off_by_default_renders_no_patches(llff_scene: Path, tmp_path: Path, monkeypatch) -> None:
    pipeline = pipeline_for(llff_scene, tmp_path)
    assert pipeline.model.config.depth_smoothness_weight == 0.0

    def forbidden(*args, **kwargs):
        raise AssertionError("no unseen-view patch may be drawn when depth smoothness is off")

    monkeypatch.setattr(pipeline.datamanager, "unseen_patches", forbidden)
    _, metrics = pipeline.train_step(0)
    assert "depth_smoothness" not in metrics


def test_the_term_is_finite_and_reaches_the_density_grids(llff_scene: Path, tmp_path: Path) -> None:
    pipeline = pipeline_for(llff_scene, tmp_path, *ON)
    model = pipeline.model
    origins, directions = pipeline.datamanager.unseen_patches(3, 4, pipeline.unseen_generator)
    model.prepare(0)
    term = model.unseen_loss(smoothness(model), origins, directions)
    assert term.ndim == 0 and torch.isfinite(term) and float(term.detach()) >= 0.0
    term.backward()
    assert_gradients_reach_the_density_grids(model)
    model.zero_grad()
    loss, metrics = pipeline.train_step(1)
    assert "depth_smoothness" in metrics and torch.isfinite(loss)
    assert_loss_is_the_sum_of_its_terms(metrics)


def test_patches_are_ndc_rays_from_the_near_plane(llff_scene: Path, tmp_path: Path) -> None:
    """NDC maps the near plane to z = -1: every patch ray starts there, and the rays point into the box (dz > 0)."""
    pipeline = pipeline_for(llff_scene, tmp_path, *ON)
    origins, directions = pipeline.datamanager.unseen_patches(5, 4, pipeline.unseen_generator)
    assert origins.shape == directions.shape == (5 * 16, 3)
    torch.testing.assert_close(origins[:, 2], torch.full((80,), -1.0), rtol=0, atol=1e-5)
    assert bool((directions[:, 2] > 0).all())


def test_a_patch_larger_than_the_images_is_one_clear_error(llff_scene: Path, tmp_path: Path) -> None:
    with pytest.raises(UserError, match="depth-smoothness-patch-size 8 does not fit the 8×6"):
        pipeline_for(llff_scene, tmp_path, "--pipeline.model.depth-smoothness-weight", "0.1")


def test_turning_it_on_keeps_the_training_batches_and_their_jitter(llff_scene: Path, tmp_path: Path) -> None:
    assert_same_training_batches(llff_scene, tmp_path, *ON, term="depth_smoothness")


def test_a_checkpoint_keeps_the_patches_stream(llff_scene: Path, tmp_path: Path) -> None:
    """Resuming draws the patches an uninterrupted run would have drawn next (the stream is in the state)."""
    pipeline = pipeline_for(llff_scene, tmp_path, *ON)
    state = pipeline.state_dict()
    assert "unseen_generator" in state
    following = pipeline.datamanager.unseen_patches(2, 4, pipeline.unseen_generator)
    pipeline.unseen_generator.manual_seed(12345)  # elsewhere in the stream
    pipeline.load_state_dict(state)
    again = pipeline.datamanager.unseen_patches(2, 4, pipeline.unseen_generator)
    for a, b in zip(following, again, strict=True):
        torch.testing.assert_close(a, b, rtol=0, atol=0)
    assert "unseen_generator" not in pipeline_for(llff_scene, tmp_path / "off").state_dict()


def test_on_an_object_with_a_background_it_warns(tmp_path: Path, capsys) -> None:
    """Misses read as the far plane, so silhouettes are true depth jumps: the user is told at start."""
    pipeline_for(TINY_SCENE, tmp_path, "--pipeline.model.depth-smoothness-weight", "0.1")
    assert "depth smoothness on a scene with a background" in capsys.readouterr().out


def test_on_forward_facing_photos_it_does_not_warn(llff_scene: Path, tmp_path: Path, capsys) -> None:
    pipeline_for(llff_scene, tmp_path, *ON)
    assert "depth smoothness on a scene with a background" not in capsys.readouterr().out


def test_the_patches_decode_no_colour(llff_scene: Path, tmp_path: Path, monkeypatch) -> None:
    """The patches are scored on their depth only: their render never calls the colour decoder."""
    pipeline = pipeline_for(llff_scene, tmp_path, *ON)
    model = pipeline.model
    origins, directions = pipeline.datamanager.unseen_patches(3, 4, pipeline.unseen_generator)
    model.prepare(0)
    monkeypatch.setattr(model.field, "rgb", lambda *a, **k: pytest.fail("colour decoded for an unseen patch"))
    assert torch.isfinite(model.unseen_loss(smoothness(model), origins, directions))
