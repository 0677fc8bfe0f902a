"""What a scene declares (background, ray space, occlusion term, ...), how overrides win, and the real-scene preset.

Blender pipelines must run nothing NDC-specific; LLFF pipelines get NDC rays, black backgrounds and FreeNeRF's
occlusion term; the effective choices land in the config. The real-scene preset replaces only values the user left
at the method preset's defaults.
"""

from __future__ import annotations

import copy
import json
import math
from pathlib import Path

import pytest
import torch

from fourierf_plugin.data.dataparser_base import SceneDeclaration
from fourierf_plugin.data.parsers.llff import LLFF_DECLARATION, NDC_BOX
from fourierf_plugin.engine.optimizers import build_optimizer
from fourierf_plugin.engine.scene_presets import (
    REAL_SCENE_SETTINGS,
    VM_REAL_SCENE_SETTINGS,
    apply_real_scene_preset,
)
from fourierf_plugin.engine.trainer import Trainer
from fourierf_plugin.fields.fourier_tensorf_field import FieldConfig
from fourierf_plugin.method_configs import all_methods
from fourierf_plugin.model_components.gradient_scaling import floaters_scale, scale_gradient
from fourierf_plugin.models.fourierf import FourieRFModelConfig, occlusion_penalty, resolve_effects
from fourierf_plugin.scripts.train import parse_args
from tests.helpers import TINY_FLAGS, TINY_SCENE, ndc_model, single_torch_thread  # noqa: F401 - autouse fixture
from tests.test_llff_parser import write_llff_scene

ITERS = 50


def _get(obj, path: str):
    for part in path.split("."):
        obj = getattr(obj, part)
    return obj


@pytest.fixture(scope="module")
def llff_scene(tmp_path_factory) -> Path:
    """A 20-image synthetic LLFF scene with 8x6 images (see test_llff_parser)."""
    return write_llff_scene(tmp_path_factory.mktemp("llff") / "scene")


def _args(data: Path, out: Path, method: str = "fourierf-vm", extra: list[str] | None = None) -> list[str]:
    parser = ["llff-data", "--num-views", "3"] if (data / "poses_bounds.npy").exists() else []
    return [
        method,
        "--data",
        str(data),
        "--output-dir",
        str(out),
        "--max-num-iterations",
        str(ITERS),
        *TINY_FLAGS,
        *(extra or []),
        *parser,
    ]


def _pipeline(data: Path, out: Path, extra: list[str] | None = None):
    config = parse_args(_args(data, out, extra=extra))
    pipeline = config.pipeline.setup(
        device=torch.device("cpu"), max_iters=ITERS, generator=torch.Generator().manual_seed(0)
    )
    return config, pipeline


# -- resolve_effects ------------------------------------------------------------------------------------------------


def test_none_overrides_keep_the_declaration() -> None:
    assert resolve_effects(LLFF_DECLARATION, FourieRFModelConfig()) == LLFF_DECLARATION
    assert resolve_effects(SceneDeclaration(), FourieRFModelConfig()) == SceneDeclaration()


def test_explicit_overrides_win() -> None:
    cfg = FourieRFModelConfig(
        background="random", view_dependent=True, ray_space="euclidean", occlusion_regularization=False
    )
    got = resolve_effects(LLFF_DECLARATION, cfg)
    assert (got.background, got.view_dependent, got.ray_space, got.occlusion_regularization) == (
        "random",
        True,
        "euclidean",
        False,
    )
    assert got.bounded is False, "boundedness is the scene's, not overridable by the model"
    only_bg = resolve_effects(LLFF_DECLARATION, FourieRFModelConfig(background="white"))
    assert only_bg == SceneDeclaration(
        background="white", ray_space="ndc", bounded=False, view_dependent=False, occlusion_regularization=True
    )


# -- pipelines ------------------------------------------------------------------------------------------------------


def test_blender_pipeline_is_euclidean_without_occlusion(tmp_path: Path) -> None:
    config, pipeline = _pipeline(TINY_SCENE, tmp_path)
    model = pipeline.model
    assert model.ray_space == "euclidean" and model.background == "white"
    assert pipeline.datamanager.ray_space == "euclidean"
    rays = pipeline.datamanager.train_rays
    torch.testing.assert_close(rays.directions.norm(dim=-1), torch.ones(rays.directions.shape[0]))
    _, metrics = pipeline.train_step(0)
    assert "occlusion" not in metrics
    m = config.pipeline.model
    assert (m.background, m.view_dependent, m.ray_space, m.occlusion_regularization) == (
        "white",
        False,
        "euclidean",
        False,
    )


def test_llff_pipeline_uses_ndc_black_and_occlusion(tmp_path: Path, llff_scene: Path) -> None:
    config, pipeline = _pipeline(llff_scene, tmp_path)
    model = pipeline.model
    assert model.ray_space == "ndc" and pipeline.datamanager.ray_space == "ndc"
    rays = pipeline.datamanager.train_rays
    torch.testing.assert_close(rays.origins[:, 2], torch.full_like(rays.origins[:, 2], -1.0))
    model.prepare(0)
    out = model(rays.origins[:64], rays.directions[:64], training=True)
    assert "occlusion" in out and math.isfinite(out["occlusion"].item())
    bg = out["background"]
    assert bool((bg == 0).all() or (bg == 1).all()), "photos (background none) train on black or white per batch"
    loss, metrics = pipeline.train_step(0)
    assert "occlusion" in metrics and math.isfinite(metrics["occlusion"]) and torch.isfinite(loss)
    assert model._eval_background() == "black"
    view = next(pipeline.render_views("test", 0))
    assert bool(torch.isfinite(view.rgb).all()) and tuple(view.rgb.shape) == (6, 8, 3)
    m = config.pipeline.model
    assert (m.background, m.view_dependent, m.ray_space, m.occlusion_regularization) == (
        "none",
        False,
        "ndc",
        True,
    )


def test_occlusion_override_removes_the_term(tmp_path: Path, llff_scene: Path) -> None:
    config, pipeline = _pipeline(llff_scene, tmp_path, ["--pipeline.model.occlusion-regularization", "False"])
    _, metrics = pipeline.train_step(0)
    assert "occlusion" not in metrics
    assert config.pipeline.model.occlusion_regularization is False
    assert pipeline.model.ray_space == "ndc", "the other declared effects stay"


def test_background_override_reaches_training(tmp_path: Path, llff_scene: Path) -> None:
    config, pipeline = _pipeline(llff_scene, tmp_path, ["--pipeline.model.background", "white"])
    rays = pipeline.datamanager.train_rays
    pipeline.model.prepare(0)
    out = pipeline.model(rays.origins[:8], rays.directions[:8], training=True)
    assert bool((out["background"] == 1).all())
    assert config.pipeline.model.background == "white"


# Regression: with a plain black background and softplus(x - 10) densities, every weight of a fresh LLFF model is
# below the 1e-4 shading threshold, so no colour is evaluated and d rgb / d w = c - bg = 0: the photometric loss gave
# the density grid exactly zero gradient and training never started. Photos now declare background "none" (trained
# on black or white at random per batch, TensoRF's LLFF term), which gives the density a gradient from step 0.
def test_fresh_llff_model_learns_a_constant_colour() -> None:
    """80 steps on a grey target seen by a camera at the origin: the (black-evaluated) render must turn grey."""
    config = copy.deepcopy(all_methods["fourierf-vm"])
    apply_real_scene_preset(config, all_methods["fourierf-vm"])  # what the trainer does on a forward-facing scene
    m = config.pipeline.model
    m.field.n_voxels_init = m.field.n_voxels_final = 4096
    m.field.upsample_fractions, m.occupancy_update_fractions = (), ()
    torch.manual_seed(0)
    model = m.setup(
        scene_box=torch.tensor(NDC_BOX),
        near=0.0,
        far=1.0,
        declaration=LLFF_DECLARATION,
        max_iters=1000,
        generator=torch.Generator().manual_seed(0),
    )
    optimizer = build_optimizer(config.optimizer, model.param_groups())
    g = torch.Generator().manual_seed(1)
    # NDC rays of a camera at the origin looking down -z: parallel, o' on the near face, d' = (0, 0, 2)
    origins = torch.cat([(torch.rand(256, 2, generator=g) - 0.5) * 2, -torch.ones(256, 1)], dim=-1)
    directions = torch.tensor([[0.0, 0.0, 2.0]]).expand(256, 3)
    target = torch.cat([torch.full((256, 3), 0.5), torch.ones(256, 1)], dim=-1)
    for step in range(80):
        model.prepare(step)
        loss = torch.stack(list(model.loss_dict(model(origins, directions, training=True), target, step).values()))
        optimizer.zero_grad()
        loss.sum().backward()
        optimizer.step()
    rgb = model.render_rays(origins, directions, 80)["rgb"]
    mse = float(((rgb - 0.5) ** 2).mean())
    assert mse < 0.01, f"after 80 steps the render is still {rgb.mean():.3f} on average (mse {mse:.3f} to grey)"


# -- occlusion penalty ----------------------------------------------------------------------------------------------


@pytest.mark.parametrize(("k", "m"), [(128, 20), (64, 10), (256, 40), (7, 1)])
def test_occlusion_penalty_sums_the_first_m_samples(k: int, m: int) -> None:
    sigma = torch.arange(3 * k, dtype=torch.float64).reshape(3, k) / k
    expected = sigma[:, :m].sum(dim=-1).mean() / k  # = mean over rays and all K samples of σ_k 1[k < M]
    torch.testing.assert_close(occlusion_penalty(sigma, 20 / 128), expected)
    masked = sigma * (torch.arange(k) < m)
    torch.testing.assert_close(occlusion_penalty(sigma, 20 / 128), masked.mean())


def test_occlusion_penalty_ignores_samples_past_m() -> None:
    sigma = torch.zeros(4, 128)
    sigma[:, 20:] = 100.0
    assert occlusion_penalty(sigma, 20 / 128).item() == 0.0
    sigma[:, 19] = 128.0
    assert occlusion_penalty(sigma, 20 / 128).item() == pytest.approx(1.0)


def test_occlusion_penalty_weight_in_the_loss(tmp_path: Path, llff_scene: Path) -> None:
    _, pipeline = _pipeline(llff_scene, tmp_path)
    model = pipeline.model
    rays = pipeline.datamanager.train_rays
    model.prepare(0)
    out = model(rays.origins[:32], rays.directions[:32], training=True)
    terms = model.loss_dict(out, rays.rgba[:32], 0)
    torch.testing.assert_close(terms["occlusion"], model.config.occlusion_weight * out["occlusion"])
    assert model.config.occlusion_weight == 0.01


# -- gradient scaling -----------------------------------------------------------------------------------------------


def test_scale_gradient_is_identity_forward_and_scales_backward() -> None:
    x = torch.tensor([1.0, -2.0, 3.0], requires_grad=True)
    scale = torch.tensor([0.5, 0.0, 1.0])
    y = scale_gradient(x, scale)
    assert torch.equal(y.detach(), x.detach())
    (y * torch.tensor([1.0, 2.0, 3.0])).sum().backward()
    torch.testing.assert_close(x.grad, torch.tensor([0.5, 0.0, 3.0]))


def test_scale_gradient_broadcasts_over_colour_channels() -> None:
    x = torch.ones(2, 3, 3, requires_grad=True)
    scale = torch.tensor([[0.25, 1.0, 0.0], [1.0, 1.0, 0.5]]).unsqueeze(-1)
    scale_gradient(x, scale).sum().backward()
    torch.testing.assert_close(x.grad, scale.expand(2, 3, 3))


def test_floaters_scale_is_clamped_t_squared() -> None:
    t = torch.tensor([0.0, 0.5, 1.0, 2.0, 6.0])
    torch.testing.assert_close(floaters_scale(t), torch.tensor([0.0, 0.25, 1.0, 1.0, 1.0]))


def _ndc_model(floaters: bool):
    # density_shift 0 gives softplus(raw) ~ 0.7: enough weight on every sample that colours are shaded too
    cfg = FourieRFModelConfig(
        field=FieldConfig(n_voxels_init=4096, n_voxels_final=13824, density_shift=0.0),
        floaters_gradient_scaling=floaters,
    )
    return ndc_model(cfg)


def _grads(floaters: bool) -> tuple[dict[str, torch.Tensor], torch.Tensor]:
    torch.manual_seed(0)  # the decoder's layers draw from the global RNG
    model = _ndc_model(floaters)
    g = torch.Generator().manual_seed(1)
    origins = torch.cat([(torch.rand(128, 2, generator=g) - 0.5) * 2, -torch.ones(128, 1)], dim=-1)
    directions = torch.cat([(torch.rand(128, 2, generator=g) - 0.5) * 0.2, torch.full((128, 1), 2.0)], dim=-1)
    target = torch.rand(128, 3, generator=g)
    model.prepare(0)
    out = model(origins, directions, training=True)
    ((out["rgb"] - target) ** 2).mean().backward()
    grads = {name: p.grad.detach().clone() for name, p in model.named_parameters() if p.grad is not None}
    return grads, out["rgb"].detach()


def test_floaters_scaling_reaches_density_and_colour() -> None:
    """Same batch and jitter with and without: identical forward, different density AND appearance gradients."""
    plain, rgb_plain = _grads(False)
    scaled, rgb_scaled = _grads(True)
    torch.testing.assert_close(rgb_plain, rgb_scaled, rtol=0, atol=0)
    assert plain.keys() == scaled.keys()
    density = [n for n in plain if n.startswith("field.density_grid")]
    appearance = [n for n in plain if n.startswith("field.appearance_grid")]
    assert density and appearance
    for names, what in ((density, "density"), (appearance, "appearance")):
        for n in names:
            assert torch.isfinite(scaled[n]).all()
        assert any(not torch.allclose(plain[n], scaled[n]) for n in names), f"{what} gradients are not scaled"
    # every NDC sample has t < 1, so the scale t² < 1 shrinks the total gradient
    total = lambda g: sum(float(v.norm() ** 2) for v in g.values())  # noqa: E731
    assert total(scaled) < total(plain)


def test_floaters_scaling_is_off_by_default_and_at_eval() -> None:
    assert FourieRFModelConfig().floaters_gradient_scaling is False
    model = _ndc_model(True)
    model.prepare(0)
    o = torch.tensor([[0.0, 0.0, -1.0]], requires_grad=True)
    d = torch.tensor([[0.0, 0.0, 2.0]])
    out = model(o, d, training=False)  # no crash, no scaling node needed
    assert torch.isfinite(out["rgb"]).all()


# -- scene presets --------------------------------------------------------------------------------------------------


def test_real_preset_applies_every_setting_to_a_pristine_vm_config() -> None:
    pristine = all_methods["fourierf-vm"]
    config = copy.deepcopy(pristine)
    applied, kept = apply_real_scene_preset(config, pristine)
    settings = REAL_SCENE_SETTINGS | VM_REAL_SCENE_SETTINGS
    assert kept == [] and len(applied) == len(settings)
    for path, value in settings.items():
        assert _get(config, path) == value, path
    assert config.pipeline.model.fourier.f0_density == 0.01 and config.optimizer.weight_decay == 0.0
    assert config.pipeline.model.field.density_components == (16, 4, 4)
    assert config.pipeline.model.field.appearance_components == (48, 12, 12)
    assert pristine.pipeline.model.fourier.f0_density == 0.3, "the registered preset is untouched"


def test_real_preset_keeps_the_users_values(tmp_path: Path) -> None:
    config = parse_args(
        ["fourierf-vm", "--optimizer.weight-decay", "0.1", "--pipeline.model.fourier.f0-density", "0.05"]
    )
    applied, kept = apply_real_scene_preset(config, all_methods["fourierf-vm"])
    assert set(kept) == {"optimizer.weight_decay", "pipeline.model.fourier.f0_density"}
    assert config.optimizer.weight_decay == 0.1 and config.pipeline.model.fourier.f0_density == 0.05
    assert config.pipeline.model.fourier.f0_color == 0.01
    assert not any(a.startswith(("weight_decay=", "f0_density=")) for a in applied)


def test_real_preset_leaves_cp_component_counts() -> None:
    pristine = all_methods["fourierf-cp"]
    config = copy.deepcopy(pristine)
    applied, _ = apply_real_scene_preset(config, pristine)
    assert config.pipeline.model.field.density_components == (96, 96, 96)
    assert config.pipeline.model.field.appearance_components == (288, 288, 288)
    assert len(applied) == len(REAL_SCENE_SETTINGS)
    assert config.pipeline.model.fourier.f0_density == 0.01


def test_real_preset_without_a_pristine_applies_everything() -> None:
    config = copy.deepcopy(all_methods["fourierf-vm"])
    config.optimizer.weight_decay = 0.3
    applied, kept = apply_real_scene_preset(config, None)
    assert kept == [] and len(applied) == len(REAL_SCENE_SETTINGS | VM_REAL_SCENE_SETTINGS)
    assert config.optimizer.weight_decay == 0.0


def _saved_config(run_dir: Path) -> dict:
    return json.loads((run_dir / "config.json").read_text())["config"]


def test_trainer_picks_the_real_preset_on_llff(tmp_path: Path, llff_scene: Path, capsys) -> None:
    trainer = Trainer(parse_args(_args(llff_scene, tmp_path)))
    saved = _saved_config(trainer.run_dir)
    assert saved["scene_preset"] == "real"
    assert saved["pipeline"]["model"]["fourier"]["f0_density"] == 0.01
    assert saved["optimizer"]["weight_decay"] == 0.0
    model = saved["pipeline"]["model"]
    assert (model["background"], model["ray_space"], model["occlusion_regularization"], model["view_dependent"]) == (
        "none",
        "ndc",
        True,
        False,
    )
    printed = capsys.readouterr().out
    assert "real-scene preset" in printed and "forward-facing" in printed
    assert "scene effects" in printed


def test_trainer_stays_synthetic_on_blender(tmp_path: Path) -> None:
    trainer = Trainer(parse_args(_args(TINY_SCENE, tmp_path)))
    saved = _saved_config(trainer.run_dir)
    assert saved["scene_preset"] == "synthetic"
    assert saved["pipeline"]["model"]["fourier"]["f0_density"] == 0.3
    assert saved["optimizer"]["weight_decay"] == 0.2
    assert saved["pipeline"]["model"]["ray_space"] == "euclidean"


def test_forced_synthetic_preset_on_llff_keeps_synthetic_values(tmp_path: Path, llff_scene: Path) -> None:
    trainer = Trainer(parse_args(_args(llff_scene, tmp_path, extra=["--scene-preset", "synthetic"])))
    saved = _saved_config(trainer.run_dir)
    assert saved["scene_preset"] == "synthetic"
    assert saved["pipeline"]["model"]["fourier"]["f0_density"] == 0.3
    assert saved["optimizer"]["weight_decay"] == 0.2
    assert saved["pipeline"]["model"]["ray_space"] == "ndc", "the scene's effects do not depend on the preset"


def test_user_flag_survives_the_automatic_real_preset(tmp_path: Path, llff_scene: Path) -> None:
    trainer = Trainer(parse_args(_args(llff_scene, tmp_path, extra=["--optimizer.weight-decay", "0.1"])))
    saved = _saved_config(trainer.run_dir)
    assert saved["scene_preset"] == "real" and saved["optimizer"]["weight_decay"] == 0.1
    assert saved["pipeline"]["model"]["fourier"]["f0_density"] == 0.01
