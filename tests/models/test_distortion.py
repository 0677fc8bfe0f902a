"""mip-NeRF 360's distortion loss through pipelines built the way ``fourierf-train`` builds them.

Off by default (the loss is never computed); on, it is one finite, non-negative term of the loss on both kinds of
ray (box rays of an object, NDC rays of a forward-facing scene) whose gradient reaches the density grids.
"""

from __future__ import annotations

from pathlib import Path

import torch

from fourierf_plugin.model_components.regularisers import distortion as losses
from tests.helpers import TINY_SCENE
from tests.models.test_scene_effects import (
    assert_gradients_reach_the_density_grids,
    assert_loss_is_the_sum_of_its_terms,
    forbid,
    pipeline_for,
)

ON = ("--pipeline.model.distortion-weight", "0.01")


def test_off_by_default_is_never_computed(tmp_path: Path, monkeypatch) -> None:
    pipeline = pipeline_for(TINY_SCENE, tmp_path)
    assert pipeline.model.config.distortion_weight == 0.0
    forbid(monkeypatch, "fourierf_plugin.model_components.regularisers.distortion", "distortion")
    loss, metrics = pipeline.train_step(0)
    assert "distortion" not in metrics and torch.isfinite(loss)


def test_on_it_is_a_finite_term_of_the_loss_that_reaches_the_density_grids(either_scene: Path, tmp_path: Path) -> None:
    pipeline = pipeline_for(either_scene, tmp_path, *ON)
    model = pipeline.model
    loss, metrics = pipeline.train_step(0)
    assert "distortion" in metrics and float(metrics["distortion"]) >= 0.0 and torch.isfinite(loss)
    assert_loss_is_the_sum_of_its_terms(metrics)
    model.zero_grad()
    batch = pipeline.datamanager.next_batch()
    model.prepare(1)
    outputs = model(batch.origins, batch.directions)
    model.loss_dict(outputs, batch.rgba, 1)["distortion"].backward()
    assert_gradients_reach_the_density_grids(model)


def test_it_is_taken_once_a_step_on_the_training_rays_only(llff_scene: Path, tmp_path: Path, monkeypatch) -> None:
    """With depth smoothness on too, the unseen-view patches are rendered in training mode as well; the distortion
    term is still computed once, on the training batch (the patches' rays are not scored for it)."""
    smooth = ("--pipeline.model.depth-smoothness-weight", "0.1", "--pipeline.model.depth-smoothness-patch-size", "4")
    pipeline = pipeline_for(llff_scene, tmp_path, *ON, *smooth)
    calls: list[int] = []
    original = losses.distortion

    def counted(weights: torch.Tensor, s: torch.Tensor) -> torch.Tensor:
        calls.append(weights.shape[0])
        return original(weights, s)

    monkeypatch.setattr(losses, "distortion", counted)
    _, metrics = pipeline.train_step(0)
    assert "depth_smoothness" in metrics and "distortion" in metrics
    manager = pipeline.datamanager
    assert calls == [min(manager.config.rays_per_batch, int(manager.active.numel()))]  # the training batch's rays
