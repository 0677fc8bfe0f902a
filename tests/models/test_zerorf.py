"""zerorf-vm in the pipeline: the preset, the field behind the model's interface, structure changes that keep the
generators' parameters and optimiser state, training, resume, evaluation, render and export, bad options."""

from __future__ import annotations

import copy
import json
from dataclasses import replace
from pathlib import Path

import pytest
import torch

from fourierf_plugin.accel import AccelConfig
from fourierf_plugin.configs.base import from_dict, load_config, to_dict
from fourierf_plugin.data.parsers.blender import BLENDER_DECLARATION
from fourierf_plugin.engine.estimates import checkpoint_bytes, estimate_seconds
from fourierf_plugin.engine.optimizers import OptimizerConfig, build_optimizer
from fourierf_plugin.engine.option_checks import check_training_options
from fourierf_plugin.engine.trainer import TrainerConfig
from fourierf_plugin.field_components.generator import ZeroRFConfig, parameter_count
from fourierf_plugin.fields.fourier_tensorf_field import FieldConfig
from fourierf_plugin.fields.zerorf_field import ZeroRFField
from fourierf_plugin.method_configs import all_methods, config_registry
from fourierf_plugin.model_components.marching import densities, densities_that_show
from fourierf_plugin.model_components.occupancy import shrink_bounds
from fourierf_plugin.model_components.rendering import composite_weights
from fourierf_plugin.models.fourierf import FourieRFModel, FourieRFModelConfig
from fourierf_plugin.models.zerorf import ZeroRFModelConfig, generator_config
from fourierf_plugin.scripts import train as train_script
from fourierf_plugin.scripts.cli import EXIT_USER_ERROR
from fourierf_plugin.scripts.train import parse_args
from fourierf_plugin.utils.errors import UserError
from tests.helpers import (
    TINY_FINAL_RESO,
    assert_same_model_state,
    cli_exit_code,
    evaluate_render_and_export,
    rays_through_the_slab,
    resumed_and_uninterrupted,
    slab_model,
    tiny_args,
    train_tiny,
)

SMALL_FLAGS = [
    "--pipeline.model.zerorf.plane-channels", "64", "32", "32",
    "--pipeline.model.zerorf.line-channels", "32", "32", "32",
]  # fmt: skip
"""Narrow generators for the runs that test the pipeline rather than ZeroRF's widths (a few times faster)."""
BOX = torch.tensor([[-1.5] * 3, [1.5] * 3])


def _model(max_iters: int = 20, **model_changes) -> FourieRFModel:
    """zerorf-vm's model on the Blender box, 16³ → 24³, with narrow generators."""
    preset = all_methods["zerorf-vm"].pipeline.model
    config = copy.deepcopy(preset)
    config.field.n_voxels_init, config.field.n_voxels_final = 16**3, 24**3
    config.zerorf.plane_channels, config.zerorf.line_channels = (64, 32), (32, 32)
    for key, value in model_changes.items():
        setattr(config, key, value)
    return config.setup(
        scene_box=BOX, near=2.0, far=6.0, effects=BLENDER_DECLARATION, max_iters=max_iters,
        generator=torch.Generator().manual_seed(0),
    )  # fmt: skip


def _points(n: int = 512, seed: int = 0, box: torch.Tensor = BOX) -> torch.Tensor:
    u = torch.rand(n, 3, generator=torch.Generator().manual_seed(seed))
    return box[0] + u * (box[1] - box[0])


# -- the preset -----------------------------------------------------------------------------------------------------
def test_the_preset_is_zerorf_on_the_same_pipeline() -> None:
    config = parse_args(["zerorf-vm"])
    assert config.method_name == "zerorf-vm"
    model, optimizer = config.pipeline.model, config.optimizer
    assert isinstance(model, ZeroRFModelConfig) and not model.fourier.enabled
    assert model.tv_weight_density == model.tv_weight_appearance == model.l1_weight_initial == 0.0
    assert model == ZeroRFModelConfig(), "the preset is ZeroRF's model config at its defaults"
    assert (optimizer.lr_generator, optimizer.betas, optimizer.weight_decay) == (2e-3, (0.9, 0.98), 0.2)
    assert optimizer.lr_decay_ratio == 1.0
    assert config.pipeline.effects.view_dependent is True
    check_training_options(config)
    again = from_dict(json.loads(json.dumps(to_dict(config))), TrainerConfig)
    assert again == config == all_methods["zerorf-vm"]


def test_the_other_grid_presets_keep_free_factors() -> None:
    for name, preset in all_methods.items():
        if name not in ("zerorf-vm", "freenerf"):  # freenerf's field is an MLP (tests/models/test_freenerf.py)
            assert generator_config(preset.pipeline.model) is None, name
            assert type(preset.pipeline.model) is FourieRFModelConfig, name


# -- the field behind the model's interface ---------------------------------------------------------------------------
def test_the_model_builds_the_zerorf_field_with_one_optimiser_group() -> None:
    model = _model()
    assert isinstance(model.field, ZeroRFField)
    assert model.field.resolution == [16, 16, 16]
    assert model.field.grid.canvas_resolution == [24, 24, 24], "the canvas covers the final grid (noise 12, ×2)"
    groups = model.param_groups()
    assert list(groups) == ["generator"]
    assert {id(p) for p in groups["generator"]} == {id(p) for p in model.parameters()}
    optimizer = build_optimizer(OptimizerConfig(lr_generator=5e-3), groups)
    assert [g["lr"] for g in optimizer.param_groups] == [5e-3]


def test_the_generator_gradient_is_clipped_before_each_step() -> None:
    model = _model()
    params = model.param_groups()["generator"]
    optimizer = build_optimizer(OptimizerConfig(generator_grad_clip=0.32), model.param_groups())
    for p in params:
        p.grad = torch.full_like(p, 10.0)
    optimizer.step()
    norm = torch.linalg.vector_norm(torch.stack([torch.linalg.vector_norm(p.grad) for p in params]))
    assert float(norm) == pytest.approx(0.32, rel=1e-4)


def test_density_and_colour_have_gradients_to_the_generators() -> None:
    model = _model()
    model.prepare(0)
    xyz = _points()
    dirs = torch.nn.functional.normalize(torch.randn(xyz.shape[0], 3), dim=-1)
    sigma, rgb = model.field.density(xyz), model.field.rgb(xyz, dirs)
    assert sigma.shape == (512,) and rgb.shape == (512, 3)
    assert bool((sigma >= 0).all()) and torch.isfinite(rgb).all()
    (sigma.mean() + rgb.mean()).backward()
    conv_out = [p for name, p in model.named_parameters() if name.endswith("conv_out.weight")]
    assert len(conv_out) == 6 and all(float(p.grad.abs().max()) > 0 for p in conv_out), "every generator gets one"


def test_structure_changes_keep_the_parameters_and_the_optimiser() -> None:
    model = _model(max_iters=20)
    assert model.reset_steps() == [], "no learning-rate restarts: nothing is replaced"
    before = {name: p for name, p in model.named_parameters()}
    step = model.upsample_steps[0]
    changes = model.after_step(step)
    assert not changes.params_replaced, "the trainer keeps its optimiser (and its moments)"
    assert model.field.resolution != [16, 16, 16]
    after = dict(model.named_parameters())
    assert all(after[name] is p for name, p in before.items())


def test_a_crop_keeps_the_field_where_it_was() -> None:
    """The occupancy shrink narrows the window the canvas is read from: inside the new box nothing changes."""
    model = _model()
    model.field.upsample(TINY_FINAL_RESO)
    occupied = torch.tensor([[-0.8, -0.5, -1.0], [0.6, 0.9, 0.4]])
    lo, hi, box = shrink_bounds(occupied, model.aabb, model.field.resolution)
    inside = _points(seed=3, box=box)
    with torch.no_grad():
        model.field.invalidate()
        model.prepare(0)
        before = model.field.density(inside)
        model.field.crop(lo, hi, box)
        model.field.invalidate()
        model.prepare(0)
        after = model.field.density(inside)
    assert model.field.resolution == [h - low for low, h in zip(lo, hi, strict=True)]
    assert torch.equal(model.aabb, box)
    torch.testing.assert_close(after, before, rtol=1e-4, atol=1e-6)


def test_a_saved_cropped_model_loads_into_a_fresh_one() -> None:
    model = _model()
    model.field.upsample(TINY_FINAL_RESO)
    model.field.crop(*shrink_bounds(torch.tensor([[-0.8, -0.5, -1.0], [0.6, 0.9, 0.4]]), model.aabb, [24] * 3))
    fresh = _model()
    fresh.load_state_dict(model.state_dict())
    assert fresh.field.resolution == model.field.resolution
    assert torch.equal(fresh.aabb, model.aabb)
    origins = torch.tensor([[0.0, -4.0, 0.3]]).expand(16, 3).contiguous()
    directions = torch.nn.functional.normalize(torch.randn(16, 3) * 0.1 + torch.tensor([0.0, 1.0, 0.0]), dim=-1)
    a, b = model.render_rays(origins, directions, 0), fresh.render_rays(origins, directions, 0)
    for key in ("rgb", "accumulation", "depth"):
        assert torch.equal(a[key], b[key]), key


# -- training, resume, evaluation ----------------------------------------------------------------------------------
@pytest.mark.slow
def test_a_short_training_lowers_the_loss(tmp_path: Path) -> None:
    """ZeroRF's own generator widths (canvas 32² for the tiny grid)."""
    _, run_dir = train_tiny(tmp_path, method="zerorf-vm", iters=30, extra=["--log-every", "1"])
    records = [json.loads(line) for line in (run_dir / "metrics.jsonl").read_text().splitlines()]
    mse = [r["mse"] for r in records if "mse" in r]
    assert len(mse) == 30
    assert sum(mse[-5:]) / 5 < 0.6 * sum(mse[:5]) / 5


@pytest.mark.slow
def test_a_resumed_run_ends_where_an_uninterrupted_run_ends(tmp_path: Path) -> None:
    """Upsamples at 9 and 21, occupancy updates at 6 and 12 (ray filtering): resuming at 10 crosses both kinds."""
    uninterrupted, resumed = resumed_and_uninterrupted(tmp_path, "zerorf-vm", 30, 10, SMALL_FLAGS)
    assert_same_model_state(uninterrupted, resumed)
    assert uninterrupted.pipeline.model.field.resolution == resumed.pipeline.model.field.resolution == TINY_FINAL_RESO


@pytest.mark.slow
def test_evaluation_render_and_export_read_a_zerorf_run(tmp_path: Path) -> None:
    _, run_dir = train_tiny(tmp_path / "train", method="zerorf-vm", iters=12, extra=SMALL_FLAGS)
    config_path = run_dir / "config.json"
    saved = json.loads(config_path.read_text())["config"]
    assert saved["method_name"] == "zerorf-vm" and saved["pipeline"]["model"]["_type"] == "ZeroRFModelConfig"
    report = evaluate_render_and_export(config_path, tmp_path)
    assert 5.0 < report["results"]["psnr"] < 60.0


# -- bad options ---------------------------------------------------------------------------------------------------
@pytest.mark.parametrize(
    ("changes", "flag"),
    [
        ({"noise_channels": 0}, "--pipeline.model.zerorf.noise-channels 0"),
        ({"feature_channels": 0}, "--pipeline.model.zerorf.feature-channels 0"),
        ({"plane_channels": (256, 100)}, "--pipeline.model.zerorf.plane-channels 256 100"),
        ({"line_channels": (128, 40)}, "--pipeline.model.zerorf.line-channels 128 40"),
        ({"noise_resolution": -4}, "--pipeline.model.zerorf.noise-resolution -4"),
    ],
)
def test_bad_generator_options_are_user_errors_naming_the_flag(changes: dict, flag: str) -> None:
    config = copy.deepcopy(all_methods["zerorf-vm"])
    for key, value in changes.items():
        setattr(config.pipeline.model.zerorf, key, value)
    with pytest.raises(UserError) as info:
        check_training_options(config)
    assert flag in info.value.problem and "ZeroRF's value" in (info.value.fix or "")


def test_density_axes_are_refused_for_generated_factors() -> None:
    config = copy.deepcopy(all_methods["zerorf-vm"])
    config.pipeline.model.fourier.enabled = True  # the band on, so only the field can refuse
    check_training_options(config)
    config.pipeline.model.fourier.density_axes = (0, 1)
    with pytest.raises(UserError) as info:
        check_training_options(config)
    assert "--pipeline.model.fourier.density-axes 0 1" in info.value.problem and "ZeroRF" in info.value.problem


def test_the_cli_rejects_zero_noise_channels_with_exit_2(tmp_path: Path) -> None:
    args = tiny_args(tmp_path, "zerorf-vm", iters=2, extra=["--pipeline.model.zerorf.noise-channels", "0"])
    assert cli_exit_code(train_script.main, args) == EXIT_USER_ERROR
    assert not list(tmp_path.rglob("config.json")), "nothing was written"


def test_an_unknown_optimiser_group_is_a_clear_error() -> None:
    with pytest.raises(ValueError, match="mystery"):
        build_optimizer(OptimizerConfig(), {"mystery": [torch.nn.Parameter(torch.zeros(1))]})


def test_zerorf_is_a_model_config_of_its_own() -> None:
    assert not hasattr(FieldConfig(), "zerorf") and not hasattr(FourieRFModelConfig(), "zerorf")
    assert ZeroRFModelConfig().zerorf == ZeroRFConfig()
    assert issubclass(ZeroRFModelConfig._target, FourieRFModel)


def test_the_cost_estimate_counts_the_generators() -> None:
    """The line printed before training: zerorf-vm's checkpoints hold its generators, and its iterations cost more."""
    zerorf, tensorf = copy.deepcopy(all_methods["zerorf-vm"]), copy.deepcopy(all_methods["tensorf-vm"])
    for config in (zerorf, tensorf):
        config.max_num_iterations = 800
        config.pipeline.datamanager.rays_per_batch = 1024
        config.pipeline.model.field.n_voxels_final = 128**3
    assert estimate_seconds(zerorf, 2) > 4 * estimate_seconds(tensorf, 2)
    expected = parameter_count(zerorf.pipeline.model.zerorf) * 4 * 3 + 1e6
    assert checkpoint_bytes(zerorf, 0) == pytest.approx(expected)


def test_renders_read_the_shared_layer_from_a_dense_table_with_the_same_numbers() -> None:
    model = _model()
    xyz = _points(seed=5)
    model.prepare(0)  # training form: six lookups and the shared layer per point
    direct = model.field.decoder.hidden(model.field.features(xyz)).detach()
    with torch.no_grad():
        model.field.prepare(1.0, 1.0)
        rendered = model.field.hidden(xyz)
        cache = model.field.filtered.density.cache
    assert cache.get("dense_appearance") is not None, "the render baked the table"
    torch.testing.assert_close(rendered, direct, atol=1e-4, rtol=1e-4)


def test_occlusion_culling_keeps_gradients_only_where_samples_show() -> None:
    """ZeroRF's culling: σ is exact where a sample's weight exceeds the threshold and 0 elsewhere (empty space and
    what lies behind the slab), the image barely changes, and only the kept samples are read with gradients."""
    model = slab_model(slab_density=50.0)
    model.train()
    model.prepare(0)
    origins, directions = rays_through_the_slab()
    samples = model.sample(origins, directions)
    calls: list[tuple[int, bool]] = []

    def density(points: torch.Tensor) -> torch.Tensor:
        calls.append((points.shape[0], torch.is_grad_enabled()))
        return model.field.density(points)

    scale = model.config.distance_scale
    full = densities(model.field.density, samples, model.occupancy).detach()
    culled = densities_that_show(density, samples, model.occupancy, scale, 1e-4)
    weights = composite_weights(full, samples.deltas, scale)
    shown = weights > 1e-4
    assert 0 < int(shown.sum()) < shown.numel() // 2, "precondition: most samples are culled"
    torch.testing.assert_close(culled.detach()[shown], full[shown])
    assert float(culled.detach()[~shown].abs().max()) == 0.0
    (first, first_grad), (second, second_grad) = calls
    assert not first_grad and second_grad and second == int(shown.sum()) < first
    image_full = (weights.unsqueeze(-1) * 0.5).sum(1)
    image_culled = (composite_weights(culled.detach(), samples.deltas, scale).unsqueeze(-1) * 0.5).sum(1)
    torch.testing.assert_close(image_culled, image_full, atol=1e-3, rtol=0)


def test_a_format_2_config_json_loads_as_zerorfs_model_config(tmp_path: Path) -> None:
    """config.json of format 2 kept ZeroRF as ``field.zerorf.enabled``; it loads as ZeroRF's model config, and the
    plain grid operations' old name as their new one."""
    config = to_dict(all_methods["zerorf-vm"])
    model = config["pipeline"]["model"]
    model["_type"] = "FourieRFModelConfig"
    model["field"]["zerorf"] = {"_type": "ZeroRFConfig", "enabled": True, **to_dict(model.pop("zerorf"))}
    model["accel"]["backend"] = "reference"
    model["fourier"]["init_in_band"] = False  # an option format 2 had, at its default
    model.pop("alpha_weight")  # a term format 2 did not have
    path = tmp_path / "config.json"
    path.write_text(json.dumps({"fourierf_version": "0.1.0", "config_format": 2, "config": config}))
    loaded = load_config(path, TrainerConfig, config_registry())
    assert type(loaded.pipeline.model) is ZeroRFModelConfig
    assert loaded.pipeline.model.accel.backend == "reference-grid-ops"
    assert loaded.pipeline.model.alpha_weight == 0.0, "trained without the silhouette term, it resumes without it"
    preset = all_methods["zerorf-vm"].pipeline.model
    assert replace(loaded.pipeline.model, accel=AccelConfig(), alpha_weight=preset.alpha_weight) == preset


def test_a_format_3_config_json_drops_init_in_band_and_keeps_zerorf_without_the_silhouette(tmp_path: Path) -> None:
    """Format 3 carried ``fourier.init_in_band`` and no ``alpha_weight``: it loads, a ZeroRF run without the term."""
    config = to_dict(all_methods["zerorf-vm"])
    model = config["pipeline"]["model"]
    model.pop("alpha_weight")
    model["fourier"]["init_in_band"] = False
    path = tmp_path / "config.json"
    path.write_text(json.dumps({"fourierf_version": "0.1.0", "config_format": 3, "config": config}))
    loaded = load_config(path, TrainerConfig, config_registry())
    assert type(loaded.pipeline.model) is ZeroRFModelConfig and loaded.pipeline.model.alpha_weight == 0.0
    model["fourier"]["init_in_band"] = True  # a run that used the removed option is refused, not silently changed
    path.write_text(json.dumps({"fourierf_version": "0.1.0", "config_format": 3, "config": config}))
    with pytest.raises(UserError, match="init_in_band"):
        load_config(path, TrainerConfig, config_registry())
