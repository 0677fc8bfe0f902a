"""zerorf-vm's supervision and schedule as ZeroRF's: the alpha term wherever the scene's images carry alpha (its
gradient reaches the generators; without alpha the loss is the colour's alone) and ZeroRF's ray batches, scaled on a
CPU to the sized batch."""

from __future__ import annotations

import copy
from pathlib import Path

import pytest
import torch

from fourierf_plugin.data.parsers.blender import BLENDER_DECLARATION
from fourierf_plugin.data.scene_effects import SceneEffects
from fourierf_plugin.method_configs import all_methods
from fourierf_plugin.model_components.regularisers.alpha import ZERORF_ALPHA_WEIGHT, Alpha, alpha_mse
from fourierf_plugin.model_components.rendering import composite_target
from fourierf_plugin.models.fourierf import FourieRFModel
from fourierf_plugin.pipelines.base import Pipeline
from fourierf_plugin.scripts.train import build_config, parse_args
from tests.helpers import TINY_FLAGS, TINY_SCENE
from tests.models.test_scene_effects import assert_loss_is_the_sum_of_its_terms
from tests.models.test_zerorf import SMALL_FLAGS

BOX = torch.tensor([[-1.5] * 3, [1.5] * 3])
ITERS = 20


def _model(effects: SceneEffects = BLENDER_DECLARATION) -> FourieRFModel:
    """zerorf-vm's model on the Blender box, 16³ → 24³, narrow generators, for a scene with ``effects``."""
    config = copy.deepcopy(all_methods["zerorf-vm"].pipeline.model)
    config.field.n_voxels_init, config.field.n_voxels_final = 16**3, 24**3
    config.zerorf.plane_channels, config.zerorf.line_channels = (64, 32), (32, 32)
    return config.setup(
        scene_box=BOX, near=2.0, far=6.0, effects=effects, max_iters=ITERS, generator=torch.Generator().manual_seed(0)
    )


def _rays_and_target(n: int = 256) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """Rays from a camera at z = 4 looking down through the box, and an RGBA target: an opaque grey disc on an empty
    background (premultiplied colour)."""
    g = torch.Generator().manual_seed(1)
    xy = (torch.rand(n, 2, generator=g) - 0.5) * 2.0
    origins = torch.cat([xy, torch.full((n, 1), 4.0)], dim=-1)
    directions = torch.tensor([0.0, 0.0, -1.0]).expand(n, 3).clone()
    alpha = (xy.norm(dim=-1) < 0.6).float()
    rgba = torch.cat([0.5 * alpha[:, None].expand(n, 3), alpha[:, None]], dim=-1)
    return origins, directions, rgba


def _pipeline(data: Path, out: Path, *flags: str) -> Pipeline:
    parser = ["llff-data", "--num-views", "3"] if (data / "poses_bounds.npy").exists() else []
    args = ["zerorf-vm", "--data", str(data), "--output-dir", str(out), "--max-num-iterations", str(ITERS)]
    config, _ = build_config(parse_args([*args, *TINY_FLAGS, *SMALL_FLAGS, *flags, *parser]))
    return config.pipeline.setup(
        device=torch.device("cpu"), max_iters=ITERS, generator=torch.Generator().manual_seed(0)
    )


# -- the alpha term -------------------------------------------------------------------------------------------------
def test_the_preset_fits_the_opacity_to_the_alpha_at_zerorfs_weight() -> None:
    model = all_methods["zerorf-vm"].pipeline.model
    assert model.alpha_weight == ZERORF_ALPHA_WEIGHT == pytest.approx(1 / 3)
    assert model.regularisers(BLENDER_DECLARATION, ITERS) == [Alpha(ZERORF_ALPHA_WEIGHT)]
    assert model.regularisers(SceneEffects(background="none"), ITERS) == []
    assert all_methods["fourierf-vm"].pipeline.model.regularisers(BLENDER_DECLARATION, ITERS) == []


def test_the_alpha_term_is_the_batchs_opacity_against_its_alpha_and_reaches_the_generators() -> None:
    model = _model()
    model.train()
    model.prepare(0)
    origins, directions, rgba = _rays_and_target()
    outputs = model(origins, directions)
    terms = model.loss_dict(outputs, rgba, 0)
    assert list(terms) == ["mse", "alpha"]
    expected = ZERORF_ALPHA_WEIGHT * alpha_mse(outputs["accumulation"], rgba[:, 3])
    torch.testing.assert_close(terms["alpha"], expected)
    assert float(terms["alpha"].detach()) > 0
    model.zero_grad()
    terms["alpha"].backward()
    conv_out = [p for name, p in model.named_parameters() if name.endswith("conv_out.weight")]
    assert conv_out and any(p.grad is not None and float(p.grad.abs().max()) > 0 for p in conv_out)
    assert all(p.grad is None or bool(torch.isfinite(p.grad).all()) for p in model.parameters())


def test_without_alpha_the_loss_is_the_colour_alone() -> None:
    """Photos (background "none"): no alpha term is built and the loss is the RGB MSE, the same number the model
    with the alpha term scores for the colour."""
    photos = _model(SceneEffects(background="none"))
    photos.train()
    photos.prepare(0)
    origins, directions, rgba = _rays_and_target()
    background = torch.ones(3)
    outputs = photos(origins, directions, background)
    terms = photos.loss_dict(outputs, rgba, 0)
    assert list(terms) == ["mse"]
    torch.testing.assert_close(terms["mse"], torch.mean((outputs["rgb"] - composite_target(rgba, background)) ** 2))
    objects = _model()
    objects.train()
    objects.prepare(0)
    with_alpha = objects.loss_dict(outputs, rgba, 0)
    assert list(with_alpha) == ["mse", "alpha"] and torch.equal(with_alpha["mse"], terms["mse"])


def test_a_training_step_takes_the_alpha_term_on_an_object_and_not_on_photos(llff_scene: Path, tmp_path: Path) -> None:
    objects = _pipeline(TINY_SCENE, tmp_path / "blender")
    loss, metrics = objects.train_step(0)
    assert "alpha" in metrics and float(metrics["alpha"]) > 0 and torch.isfinite(loss)
    assert_loss_is_the_sum_of_its_terms(metrics)
    photos = _pipeline(llff_scene, tmp_path / "llff")
    assert photos.effects.background == "none"
    _, metrics = photos.train_step(0)
    assert set(metrics) == {"mse", "loss", "psnr"}
    off = _pipeline(TINY_SCENE, tmp_path / "off", "--pipeline.model.alpha-weight", "0")
    _, metrics = off.train_step(0)
    assert "alpha" not in metrics


# -- the ray schedule -----------------------------------------------------------------------------------------------
def test_a_cpu_run_draws_zerorfs_schedule_at_its_sized_batch(tmp_path: Path) -> None:
    """The CPU sizing gives 1024 rays (a quarter of ZeroRF's 4096) and 800 iterations: 1024 → 4096 → 16384 at steps
    4 and 8, the schedule's shape at the sized batch."""
    args = ["zerorf-vm", "--data", str(TINY_SCENE), "--output-dir", str(tmp_path)]
    config, _ = build_config(parse_args(args))
    manager = config.pipeline.datamanager
    assert (config.max_num_iterations, manager.rays_per_batch) == (800, 1024)
    assert manager.rays_per_batch_schedule == ((0.0051, 4.0), (0.0101, 16.0))
    built = manager.setup(
        device=torch.device("cpu"), generator=torch.Generator().manual_seed(0), ray_space="euclidean", max_iters=800
    )
    assert [built.rays_at(step) for step in (0, 3, 4, 7, 8, 799)] == [1024, 1024, 4096, 4096, 16384, 16384]


def test_the_schedule_can_be_turned_off(tmp_path: Path) -> None:
    flags = ["--pipeline.datamanager.rays-per-batch-schedule", "None"]
    args = ["zerorf-vm", "--data", str(TINY_SCENE), "--output-dir", str(tmp_path), *flags]
    config, _ = build_config(parse_args(args))
    assert config.pipeline.datamanager.rays_per_batch_schedule is None
