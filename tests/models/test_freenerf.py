"""freenerf: FreeNeRF's frequency mask against hand-computed ones, and the preset through training, evaluation,
resume and its option checks."""

from __future__ import annotations

import copy
import json
import math
import subprocess
import types
from dataclasses import replace
from pathlib import Path

import pytest
import torch

from fourierf_plugin.data.scene_effects import SceneEffects
from fourierf_plugin.engine.estimates import checkpoint_bytes, estimate_seconds
from fourierf_plugin.engine.optimizers import OptimizerConfig, warmup_scale
from fourierf_plugin.engine.trainer import Trainer
from fourierf_plugin.fields.mlp_field import MLPFieldConfig, parameter_count
from fourierf_plugin.method_configs import all_methods
from fourierf_plugin.method_configs.budget import Run, rules_for
from fourierf_plugin.model_components import losses
from fourierf_plugin.model_components.rendering import composite_target
from fourierf_plugin.models.fourierf import FourieRFModel
from fourierf_plugin.models.freenerf import FreeNeRFModelConfig
from fourierf_plugin.scripts import train as train_script
from fourierf_plugin.scripts.cli import EXIT_USER_ERROR
from fourierf_plugin.scripts.eval import EvalConfig, run_eval
from fourierf_plugin.scripts.train import build_config, given_options, parse_args
from fourierf_plugin.utils.errors import UserError
from fourierf_plugin.viewer.render_service import (
    PreviewQuality,
    camera_from_dataset,
    high_frequency_energy,
    render_view,
)
from tests.conftest import require_shared
from tests.helpers import (
    BLENDER,
    TINY_FLAGS,
    TINY_INIT_RESO,
    assert_same_model_state,
    cli_exit_code,
    evaluate_render_and_export,
    resumed_and_uninterrupted,
    tiny_args,
    tiny_trainer_config,
    train_tiny,
    venv_script,
)

SMALL_MLP = [
    "--pipeline.model.mlp.depth", "3", "--pipeline.model.mlp.width", "32", "--pipeline.model.mlp.skip", "1",
    "--pipeline.model.mlp.view-width", "16", "--pipeline.datamanager.rays-per-batch", "64",
]  # fmt: skip
"""A network a tiny run trains in seconds (the preset's is 8 × 256)."""


def _model(max_iters: int = 100, effects: SceneEffects = BLENDER, **options: object) -> torch.nn.Module:
    config = FreeNeRFModelConfig(mlp=MLPFieldConfig(depth=2, width=8, skip=0, view_width=8), **options)
    box = torch.tensor([[-1.5] * 3, [1.5] * 3])
    return config.setup(
        scene_box=box,
        near=2.0,
        far=6.0,
        effects=effects,
        max_iters=max_iters,
        generator=torch.Generator().manual_seed(0),
    )


def _rays(count: int = 16) -> tuple[torch.Tensor, torch.Tensor]:
    """Rays from y = -4 towards the box's middle, slightly spread."""
    origins = torch.tensor([[0.0, -4.0, 0.3]]).repeat(count, 1)
    spread = torch.randn(count, 3, generator=torch.Generator().manual_seed(1)) * 0.1
    return origins, torch.nn.functional.normalize(spread + torch.tensor([0.0, 1.0, 0.0]), dim=-1)


def _masks(model: torch.nn.Module, step: int) -> tuple[list[float], list[float]]:
    model.prepare(step)
    filtered = model.field.filtered
    return filtered.density.cache["mask"].tolist(), filtered.appearance.cache["mask"].tolist()


@pytest.mark.parametrize(
    ("step", "positions", "directions"),
    [
        (0, [0.0] * 10, [0.0] * 4),  # the start: only the raw input is visible
        # a third of the ramp (30 of 90 steps): 10/3 position bands, 4/3 direction bands visible
        (30, [1.0, 1.0, 1.0, 1 / 3] + [0.0] * 6, [1.0, 1 / 3, 0.0, 0.0]),
        (45, [1.0] * 5 + [0.0] * 5, [1.0, 1.0, 0.0, 0.0]),  # the middle
        (90, [1.0] * 10, [1.0] * 4),  # the end of the ramp (90 % of 100 steps)
        (100, [1.0] * 10, [1.0] * 4),
    ],
)
def test_the_mask_opens_linearly_over_90_percent_of_the_run(step: int, positions: list, directions: list) -> None:
    got_positions, got_directions = _masks(_model(100), step)
    assert got_positions == pytest.approx(positions, abs=1e-6)
    assert got_directions == pytest.approx(directions, abs=1e-6)


def test_the_colour_reuses_the_density_pass_with_the_same_numbers_and_gradients() -> None:
    """In training the colour reads the trunk's output of the density pass; evaluating the trunk again gives the same
    colours and the same gradients (and counting the trunk's calls shows the pass is reused)."""
    results = []
    for reuse in (True, False):
        model = _model(100)
        model.train()
        if not reuse:
            model.colours = types.MethodType(FourieRFModel.colours, model)
        calls = []
        model.field.trunk[0].register_forward_hook(lambda *_, seen=calls: seen.append(1))
        model.prepare(50)
        out = model(*_rays(), jitter=torch.Generator().manual_seed(2))
        out["rgb"].sum().backward()
        results.append((out["rgb"].detach(), model.field.trunk[0].weight.grad.clone(), len(calls)))
    (rgb_a, grad_a, calls_a), (rgb_b, grad_b, calls_b) = results
    torch.testing.assert_close(rgb_a, rgb_b)
    torch.testing.assert_close(grad_a, grad_b)
    assert (calls_a, calls_b) == (1, 2)
    assert grad_a.abs().sum() > 0 and (rgb_a < 0.999).any(), "the rays hit the field's fog"


def test_two_levels_score_both_colours_penalise_the_second_and_train_the_network() -> None:
    """FreeNeRF's sampler: the render is the second level's, the first level's colour is scored at 0.1 of the MSE,
    the occlusion term reads the second level, and the gradient of every term reaches the network."""
    effects = replace(BLENDER, occlusion_regularization=True)
    model = _model(100, effects, samples_per_level=16)
    model.train()
    model.prepare(95)
    out = model(*_rays(), jitter=torch.Generator().manual_seed(2))
    assert model.samples_per_ray(training=True) == 32
    assert {"rgb", "rgb_coarse", "accumulation", "depth", "occlusion"} <= set(out)
    target = torch.rand(16, 4, generator=torch.Generator().manual_seed(3))
    terms = model.loss_dict(out, target, 95)
    expected = 0.1 * losses.mse(out["rgb_coarse"], composite_target(target, out["background"]))
    torch.testing.assert_close(terms["mse_coarse"], expected)
    assert not torch.equal(out["rgb"], out["rgb_coarse"]), "the second level samples other points"
    torch.stack(list(terms.values())).sum().backward()
    grad = model.field.trunk[0].weight.grad
    assert torch.isfinite(grad).all() and grad.abs().sum() > 0


def test_two_levels_render_the_same_picture_every_time_inside_near_and_far() -> None:
    model = _model(100, samples_per_level=16)
    origins, directions = _rays()
    first = model.render_rays(origins, directions, step=100)
    second = model.render_rays(origins, directions, step=100)
    for key in ("rgb", "accumulation", "depth"):
        torch.testing.assert_close(first[key], second[key], rtol=0.0, atol=0.0)
    assert ((first["depth"] >= 2.0) & (first["depth"] <= 6.0)).all()
    assert ((first["rgb"] >= 0.0) & (first["rgb"] <= 1.0)).all()


def test_warmup_rises_from_its_start_to_one() -> None:
    config = OptimizerConfig(lr_warmup_fraction=0.1, lr_warmup_start=0.01)
    assert warmup_scale(config, 0, 100) == pytest.approx(0.01)
    assert warmup_scale(config, 5, 100) == pytest.approx(0.01 + 0.99 * math.sin(math.pi / 4))
    assert warmup_scale(config, 10, 100) == warmup_scale(config, 90, 100) == 1.0


def test_the_preset_has_no_short_run_rule_and_refuses_one(tmp_path: Path) -> None:
    config = tiny_trainer_config(tmp_path, "freenerf", iters=20)
    assert not config.budget_rule
    assert config.pipeline.model.distance_scale == 1.0
    assert config.pipeline.effects.occlusion_regularization
    with pytest.raises(UserError, match="--budget-rule"):
        tiny_trainer_config(tmp_path, "freenerf", iters=20, extra=["--budget-rule", "True"])


@pytest.mark.parametrize("iterations", [100, 800, 1000, 3000, 9999])
@pytest.mark.parametrize("scene", ["synthetic", "real"])
def test_no_short_run_rule_matches_an_mlp_field(iterations: int, scene: str) -> None:
    config = replace(all_methods["freenerf"], max_num_iterations=iterations, scene_preset=scene)
    run = Run.of(config, "white")
    assert run.field == "mlp"
    assert rules_for(run) == []


def test_the_cost_estimate_counts_the_network_per_sample() -> None:
    config = replace(all_methods["freenerf"], max_num_iterations=800)
    wide = copy.deepcopy(config)
    wide.pipeline.model.mlp.width = 512
    assert estimate_seconds(wide, 2) > 3 * estimate_seconds(config, 2) > 0
    grid = replace(all_methods["fourierf-vm"], max_num_iterations=800)
    assert estimate_seconds(config, 2) > 10 * estimate_seconds(grid, 2), "an MLP per sample costs more than lookups"
    weights = parameter_count(config.pipeline.model.mlp)
    assert checkpoint_bytes(config, 0) == pytest.approx(weights * 12 + 1e6)


@pytest.mark.parametrize(
    ("flags", "named"),
    [
        (["--pipeline.model.mlp.ramp-fraction", "1.5"], "--pipeline.model.mlp.ramp-fraction"),
        (["--pipeline.model.mlp.position-bands", "-1"], "--pipeline.model.mlp.position-bands"),
        (["--pipeline.model.mlp.skip", "7"], "--pipeline.model.mlp.skip"),
        (["--pipeline.model.mlp.density-noise", "-1"], "--pipeline.model.mlp.density-noise"),
        (["--pipeline.model.tv-weight-density", "1"], "--pipeline.model.tv-weight-density"),
        (["--pipeline.model.fourier.enabled", "True"], "--pipeline.model.fourier.enabled"),
        (["--optimizer.grad-clip-norm", "-0.1"], "--optimizer.grad-clip-norm"),
        (["--optimizer.lr-warmup-fraction", "2"], "--optimizer.lr-warmup-fraction"),
        (["--pipeline.model.field.density-components", "4", "4", "4"], "--pipeline.model.field.density-components"),
        (["--optimizer.lr-grids", "0.1"], "--optimizer.lr-grids"),
        (["--pipeline.model.samples-per-level", "-1"], "--pipeline.model.samples-per-level"),
        (["--pipeline.model.resample-padding", "-0.01"], "--pipeline.model.resample-padding"),
        (["--pipeline.model.coarse-loss-weight", "-1"], "--pipeline.model.coarse-loss-weight"),
        (
            ["--pipeline.model.samples-per-level", "8", "--pipeline.model.step-ratio", "0.5"],
            "--pipeline.model.step-ratio",
        ),
        (["--pipeline.model.fourier.f0-density", "0.1"], "--pipeline.model.fourier.f0-density"),
    ],
)
def test_a_bad_option_is_one_clear_error_naming_its_flag(tmp_path: Path, flags: list[str], named: str) -> None:
    args = tiny_args(tmp_path, "freenerf", 20, flags)
    with pytest.raises(UserError) as info:
        build_config(parse_args(args), given_options(args))
    assert named in info.value.problem and info.value.fix


def _losses(run_dir: Path) -> list[float]:
    records = [json.loads(line) for line in (run_dir / "metrics.jsonl").read_text().splitlines()]
    return [r["loss"] for r in records if "loss" in r]


@pytest.fixture(scope="module")
def short_run(tmp_path_factory: pytest.TempPathFactory) -> tuple[Trainer, Path]:
    """A 40-iteration freenerf run of a small network on the bundled scene."""
    return train_tiny(tmp_path_factory.mktemp("out"), "freenerf", iters=40, extra=[*SMALL_MLP, "--log-every", "1"])


@pytest.mark.slow
def test_a_short_run_lowers_the_loss(short_run: tuple[Trainer, Path]) -> None:
    losses = _losses(short_run[1])
    assert len(losses) == 40
    assert sum(losses[-5:]) / 5 < sum(losses[:5]) / 5, f"loss went from {losses[:5]} to {losses[-5:]}"


@pytest.mark.slow
def test_a_run_evaluates_renders_and_exports(short_run: tuple[Trainer, Path], tmp_path: Path) -> None:
    config_path = short_run[1] / "config.json"
    saved = json.loads(config_path.read_text())["config"]
    assert saved["method_name"] == "freenerf" and saved["pipeline"]["model"]["_type"] == "FreeNeRFModelConfig"
    report = evaluate_render_and_export(config_path, tmp_path)
    assert report["step"] == 40 and 5.0 < report["results"]["psnr"] < 60.0


@pytest.mark.slow
def test_the_viewer_renders_a_run_at_any_share_of_the_bands(short_run: tuple[Trainer, Path]) -> None:
    """The viewer's sliders set the visible share of the bands; no band at all is a smoother picture."""
    trainer = short_run[0]
    model = trainer.pipeline.model
    camera = camera_from_dataset(trainer.pipeline.datamanager.parser.get_outputs("test").cameras, 0)
    full = render_view(model, camera, (1.0, 1.0))
    coarse = render_view(model, camera, (0.0, 0.0))
    preview = render_view(model, camera, (0.5, 0.5), quality=PreviewQuality(), render_size=(25, 25))
    assert full is not None and coarse is not None and preview is not None
    assert full.rgb.shape == preview.rgb.shape == (camera.height, camera.width, 3)
    assert high_frequency_energy(coarse.rgb) < high_frequency_energy(full.rgb)


@pytest.mark.slow
def test_a_resumed_run_ends_where_an_uninterrupted_run_ends(tmp_path: Path) -> None:
    """Occupancy updates at 8 and 16, upsamples at 12 and 28 of 40, the mask ramp over 36: resuming at 20."""
    uninterrupted, resumed = resumed_and_uninterrupted(tmp_path, "freenerf", 40, 20, SMALL_MLP)
    assert resumed.pipeline.model.field.resolution != TINY_INIT_RESO, "the resumed run crossed an upsample"
    assert_same_model_state(uninterrupted, resumed)


@pytest.mark.slow
def test_a_resumed_run_of_two_levels_ends_where_an_uninterrupted_run_ends(tmp_path: Path) -> None:
    """FreeNeRF's sampler draws both levels from the step's generator: resuming at 10 of 20 changes nothing."""
    flags = [*SMALL_MLP, "--pipeline.model.samples-per-level", "8"]
    uninterrupted, resumed = resumed_and_uninterrupted(tmp_path, "freenerf", 20, 10, flags)
    assert_same_model_state(uninterrupted, resumed)


@pytest.mark.slow
def test_a_forward_facing_scene_takes_freenerfs_llff_values_and_trains_in_ndc(tmp_path: Path) -> None:
    fern = require_shared("data", "llff", "fern")
    args = [
        "freenerf", "--data", str(fern), "--output-dir", str(tmp_path), "--max-num-iterations", "12", *TINY_FLAGS,
        *SMALL_MLP, "llff-data", "--num-views", "3", "--downscale", "16",
    ]  # fmt: skip
    config, _ = build_config(parse_args(args))
    assert config.pipeline.effects.ray_space == "ndc" and config.pipeline.effects.occlusion_regularization
    model = config.pipeline.model
    assert model.mlp.density_noise == 1.0 and model.samples_per_level == 128, "FreeNeRF's LLFF values and sampler"
    assert model.occupancy_update_fractions == () and model.field.upsample_fractions == ()
    optimizer = config.optimizer
    assert (optimizer.lr_networks, optimizer.lr_decay_ratio, optimizer.lr_warmup_start) == (2e-3, 0.01, 0.01)
    assert optimizer.grad_clip_value == optimizer.grad_clip_norm == 0.1
    run_dir = Trainer(config).train()
    report = run_eval(
        EvalConfig(load_config=run_dir / "config.json", output_path=tmp_path / "eval.json", render_dir=Path("none"))
    )
    assert 3.0 < report["results"]["psnr"] < 60.0


@pytest.mark.slow
def test_the_installed_commands_train_and_evaluate_a_freenerf_run(tmp_path: Path) -> None:
    """``fourierf-train freenerf`` for a few iterations, then ``fourierf-eval`` on its config, as a user runs them."""
    train = subprocess.run(
        [str(venv_script("fourierf-train")), *tiny_args(tmp_path, "freenerf", 6, [*SMALL_MLP, "--threads", "1"])],
        capture_output=True, text=True, timeout=600, check=False,
    )  # fmt: skip
    assert train.returncode == 0, train.stdout + train.stderr
    (config_path,) = tmp_path.rglob("config.json")
    report = tmp_path / "eval.json"
    evaluate = subprocess.run(
        [str(venv_script("fourierf-eval")), "--load-config", str(config_path), "--output-path", str(report),
         "--render-dir", "none", "--threads", "1"],
        capture_output=True, text=True, timeout=600, check=False,
    )  # fmt: skip
    assert evaluate.returncode == 0, evaluate.stdout + evaluate.stderr
    saved = json.loads(report.read_text())
    assert saved["method_name"] == "freenerf" and saved["step"] == 6 and math.isfinite(saved["results"]["psnr"])


def test_the_cli_refuses_a_bad_option_with_exit_2_and_writes_nothing(tmp_path: Path) -> None:
    args = tiny_args(tmp_path, "freenerf", 2, ["--pipeline.model.mlp.ramp-fraction", "-0.5"])
    assert cli_exit_code(train_script.main, args) == EXIT_USER_ERROR
    assert not list(tmp_path.rglob("config.json")), "nothing was written"
