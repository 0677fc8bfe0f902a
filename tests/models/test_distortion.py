"""mip-NeRF 360's distortion loss through pipelines built the way ``fourierf-train`` builds them.

Off by default (the loss is never computed); on, it is one finite, non-negative term of the loss on both kinds of
ray (box rays of an object, NDC rays of a forward-facing scene) whose gradient reaches the density grids.
"""

from __future__ import annotations

from pathlib import Path

import pytest
import torch

from fourierf_plugin.model_components import losses
from tests.helpers import TINY_SCENE
from tests.models.test_scene_effects import forbid, pipeline_for
from tests.scenes import write_llff_scene

ON = ("--pipeline.model.distortion-weight", "0.01")


@pytest.fixture(scope="module")
def llff_scene(tmp_path_factory) -> Path:
    """A 20-image synthetic LLFF scene with 8x6 images (tests/scenes.py)."""
    return write_llff_scene(tmp_path_factory.mktemp("llff") / "scene")


def test_off_by_default_is_never_computed(tmp_path: Path, monkeypatch) -> None:
    pipeline = pipeline_for(TINY_SCENE, tmp_path)
    assert pipeline.model.config.distortion_weight == 0.0
    forbid(monkeypatch, "fourierf_plugin.model_components.losses", "distortion")
    loss, metrics = pipeline.train_step(0)
    assert "distortion" not in metrics and torch.isfinite(loss)


@pytest.mark.parametrize("scene", ["blender", "llff"])
def test_on_it_is_a_finite_term_of_the_loss_that_reaches_the_density_grids(
    scene: str, llff_scene: Path, tmp_path: Path
) -> None:
    pipeline = pipeline_for(TINY_SCENE if scene == "blender" else llff_scene, tmp_path, *ON)
    model = pipeline.model
    loss, metrics = pipeline.train_step(0)
    assert "distortion" in metrics and float(metrics["distortion"]) >= 0.0 and torch.isfinite(loss)
    extra = float(metrics["loss"]) - sum(float(v) for k, v in metrics.items() if k not in ("loss", "psnr"))
    assert extra == pytest.approx(0.0, abs=1e-6)  # the term is part of the loss
    model.zero_grad()
    batch = pipeline.datamanager.next_batch()
    model.prepare(1)
    outputs = model(batch.origins, batch.directions)
    model.loss_dict(outputs, batch.rgba, 1)["distortion"].backward()
    density = [p.grad for name, p in model.named_parameters() if name.startswith("field.density_grid")]
    assert any(g is not None and bool(g.abs().sum() > 0) for g in density)
    assert all(g is None or bool(torch.isfinite(g).all()) for g in density)


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
