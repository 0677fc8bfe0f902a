"""InfoNeRF's ray entropy through pipelines built the way ``fourierf-train`` builds them.

Off by default (never computed, no unseen rays drawn); on, one finite term on the training rays and one on rays from
unseen poses, both in the loss, whose gradients reach the density grids; the unseen rays leave the training batches
alone, are counted in the start-of-run estimate, and resume from the checkpoint's stream (bad values:
tests/scripts/test_bad_inputs.py).
"""

from __future__ import annotations

from pathlib import Path

import pytest
import torch

from fourierf_plugin.model_components.regularisers import Entropy, Regulariser
from fourierf_plugin.models.fourierf import FourieRFModel
from tests.helpers import TINY_SCENE
from tests.models.test_scene_effects import (
    assert_gradients_reach_the_density_grids,
    assert_loss_is_the_sum_of_its_terms,
    assert_same_training_batches,
    forbid,
    pipeline_for,
)

ON = ("--pipeline.model.entropy-weight", "0.001", "--pipeline.model.entropy-unseen-rays", "64")


def entropy(model: FourieRFModel) -> Regulariser:
    """The model's Entropy regulariser."""
    (found,) = [r for r in model.regularisers if isinstance(r, Entropy)]
    return found


def test_off_by_default_is_never_computed(tmp_path: Path, monkeypatch) -> None:
    pipeline = pipeline_for(TINY_SCENE, tmp_path)
    assert pipeline.model.config.entropy_weight == 0.0 and pipeline.model.config.unseen_rays() == 0
    forbid(monkeypatch, "fourierf_plugin.model_components.regularisers.entropy", "ray_entropy")
    monkeypatch.setattr(pipeline.datamanager, "unseen_patches", lambda *a, **k: pytest.fail("no unseen rays"))
    _, metrics = pipeline.train_step(0)
    assert "entropy" not in metrics and "entropy_unseen" not in metrics


def test_both_terms_are_finite_parts_of_the_loss_that_reach_the_density_grids(
    either_scene: Path, tmp_path: Path
) -> None:
    pipeline = pipeline_for(either_scene, tmp_path, *ON)
    model = pipeline.model
    for step in range(3):  # a fresh field may hit nothing yet: train a little so some rays pass the threshold
        loss, metrics = pipeline.train_step(step)
        assert torch.isfinite(loss) and float(metrics["entropy"]) >= 0 and float(metrics["entropy_unseen"]) >= 0
        assert_loss_is_the_sum_of_its_terms(metrics)
    model.zero_grad()
    with torch.no_grad():  # a field every ray crosses: each term then has rays to score
        for p in model.field.density_grid.parameters():
            p.add_(0.5)
    origins, directions = pipeline.datamanager.unseen_patches(16, 1, pipeline.unseen_generator)
    model.prepare(3)
    term = model.unseen_loss(entropy(model), origins, directions)
    assert float(term.detach()) > 0
    term.backward()
    assert_gradients_reach_the_density_grids(model)


def test_the_unseen_rays_keep_the_training_batches_and_their_jitter(tmp_path: Path) -> None:
    assert_same_training_batches(TINY_SCENE, tmp_path, *ON, term="entropy_unseen")


def test_the_unseen_rays_are_counted_and_their_stream_is_checkpointed(tmp_path: Path) -> None:
    pipeline = pipeline_for(TINY_SCENE, tmp_path, *ON, "--pipeline.model.depth-smoothness-weight", "0.1")
    assert pipeline.model.config.unseen_rays() == 64 + 4 * 8**2
    assert "unseen_generator" in pipeline.state_dict()
    training_only = pipeline_for(TINY_SCENE, tmp_path / "t", *ON[:2], "--pipeline.model.entropy-unseen-rays", "0")
    assert training_only.model.config.unseen_rays() == 0 and "unseen_generator" not in training_only.state_dict()
    _, metrics = training_only.train_step(0)
    assert "entropy" in metrics and "entropy_unseen" not in metrics


def test_the_unseen_rays_decode_no_colour(tmp_path: Path, monkeypatch) -> None:
    """The unseen rays are scored on their opacities only: their render never calls the colour decoder."""
    pipeline = pipeline_for(TINY_SCENE, tmp_path, *ON)
    model = pipeline.model
    origins, directions = pipeline.datamanager.unseen_patches(16, 1, pipeline.unseen_generator)
    model.prepare(0)
    monkeypatch.setattr(model.field, "rgb", lambda *a, **k: pytest.fail("colour decoded for an unseen ray"))
    assert torch.isfinite(model.unseen_loss(entropy(model), origins, directions))
