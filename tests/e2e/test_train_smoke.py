"""End to end on the bundled scene: a few dozen iterations train, log, checkpoint, upsample and evaluate."""

from __future__ import annotations

import json
import math
from dataclasses import dataclass
from pathlib import Path

import imageio.v3 as iio
import pytest

from fourierf_plugin.engine.checkpoint import list_checkpoints
from fourierf_plugin.engine.trainer import Trainer
from fourierf_plugin.field_components import schedules
from fourierf_plugin.scripts.eval import EvalConfig, run_eval
from tests.conftest import SHARED_DIR, require_shared
from tests.helpers import (
    TINY_FINAL_RESO,
    TINY_IMAGE_SIZE,
    TINY_INIT_RESO,
    TINY_TEST_VIEWS,
    TINY_TRAIN_IDS,
    TINY_TRAIN_NAMES,
    tiny_trainer_config,
    train_tiny,
)

pytestmark = pytest.mark.slow
ITERS = 30
LPIPS_WEIGHTS = ("lpips", "lpips_alex_v0.1.pth")


def _lpips_weights() -> Path:
    """The LPIPS-alex weights in ../shared (skips, or fails under CI=true, when absent)."""
    return require_shared(*LPIPS_WEIGHTS)


@dataclass
class Run:
    trainer: Trainer
    run_dir: Path
    initial_resolution: list[int]


@pytest.fixture(scope="module")
def run(tmp_path_factory) -> Run:
    """One fourierf-vm run at the default event fractions (occupancy updates at 6 and 12, upsamples at 9 and 21)."""
    trainer = Trainer(tiny_trainer_config(tmp_path_factory.mktemp("out"), iters=ITERS, extra=["--log-every", "1"]))
    initial = list(trainer.pipeline.model.field.resolution)
    return Run(trainer, trainer.train(), initial)


def _metrics(run_dir: Path) -> list[dict]:
    return [json.loads(line) for line in (run_dir / "metrics.jsonl").read_text().splitlines()]


def test_run_directory_layout(run: Run) -> None:
    d = run.run_dir
    assert d.parent.name == "fourierf-vm" and d.parent.parent.name == "lego_tiny"
    assert (d / "config.json").is_file()
    views = json.loads((d / "views.json").read_text())
    named = {"scene": "lego_tiny", "train_view_ids": TINY_TRAIN_IDS, "train_image_names": TINY_TRAIN_NAMES}
    assert {k: views[k] for k in named} == named
    assert views["train_image_size"] == [100, 100] and len(views["train_camera_centres"]) == len(TINY_TRAIN_IDS)
    checkpoints = list_checkpoints(d / "checkpoints")
    assert checkpoints and checkpoints[-1].name == f"step-{ITERS:09d}.ckpt"


def test_metrics_log_is_jsonl_ending_with_done(run: Run) -> None:
    records = _metrics(run.run_dir)
    steps = [r["step"] for r in records[:-1]]
    assert steps == list(range(1, ITERS + 1)), "--log-every 1 logs every step once"
    assert records[-1]["event"] == "done" and records[-1]["step"] == ITERS
    assert records[-1]["train_seconds"] > 0
    for r in records[:-1]:
        assert math.isfinite(r["loss"]) and math.isfinite(r["psnr"])
        assert 0 < r["f_density"] <= 1.0
    assert records[0]["f_density"] == pytest.approx(0.3), "FourieRF starts at the low cutoff f0"
    ramp = round(run.trainer.config.pipeline.model.fourier.ramp_fraction * ITERS)
    for r in records[:-1]:  # and opens linearly over the ramp the run was configured with (the budget rule's here)
        assert r["f_density"] == pytest.approx(schedules.cutoff_at(r["step"] - 1, 0.3, ramp))


def test_training_lowers_the_loss(run: Run) -> None:
    losses = [r["loss"] for r in _metrics(run.run_dir)[:-1]]
    tail = sum(losses[-5:]) / 5  # single 256-ray batches are noisy; average the last few
    assert tail < losses[0], f"loss went from {losses[0]:.4f} to {tail:.4f}"


def test_upsample_changed_the_grid(run: Run) -> None:
    assert run.initial_resolution == TINY_INIT_RESO
    assert run.trainer.pipeline.model.field.resolution == TINY_FINAL_RESO


def test_config_records_the_effective_scene_effects(run: Run) -> None:
    """Every effect is resolved in config.json (the Blender declaration here), so a saved run never depends on the
    parser's defaults again; and the model simulated exactly those."""
    pipeline = json.loads((run.run_dir / "config.json").read_text())["config"]["pipeline"]
    assert pipeline["effects"] == {
        "_type": "EffectsConfig",
        "background": "white",
        "ray_space": "euclidean",
        "view_dependent": False,
        "occlusion_regularization": False,
    }
    assert "background" not in pipeline["model"], "the effects are no model setting any more"
    effects = run.trainer.pipeline.model.effects
    assert (effects.background, effects.ray_space, effects.view_dependent) == ("white", "euclidean", False)


@dataclass
class Evaluation:
    report: dict
    saved: dict
    render_dir: Path
    lpips_weights: Path | None


@pytest.fixture(scope="module")
def evaluation(run: Run, tmp_path_factory) -> Evaluation:
    """fourierf-eval on the test split, once (rendering dominates); LPIPS is included when ../shared is there."""
    out_dir = tmp_path_factory.mktemp("eval")
    weights = SHARED_DIR.joinpath(*LPIPS_WEIGHTS)
    weights = weights if weights.is_file() else None
    config = EvalConfig(
        load_config=run.run_dir / "config.json",
        output_path=out_dir / "eval.json",
        render_dir=out_dir / "renders",
        lpips_weights=weights,
        device="cpu",
    )
    report = run_eval(config)
    return Evaluation(report, json.loads(config.output_path.read_text()), out_dir / "renders", weights)


def test_evaluation_writes_finite_metrics(evaluation: Evaluation) -> None:
    saved = evaluation.saved
    assert saved["results"] == evaluation.report["results"]
    assert saved["step"] == ITERS and saved["split"] == "test" and saved["method_name"] == "fourierf-vm"
    assert saved["num_views"] == TINY_TEST_VIEWS == len(saved["per_image"])
    for key in ("psnr", "ssim"):
        assert math.isfinite(saved["results"][key]), key
        assert all(math.isfinite(p[key]) for p in saved["per_image"]), key
    assert 0 < saved["results"]["ssim"] <= 1


def test_evaluation_saves_one_png_per_test_view(evaluation: Evaluation) -> None:
    pngs = sorted(evaluation.render_dir.glob("*.png"))
    assert len(pngs) == TINY_TEST_VIEWS
    assert {p.stem for p in pngs} == {p["name"] for p in evaluation.saved["per_image"]}
    for png in pngs:
        assert iio.imread(png).shape == (*TINY_IMAGE_SIZE, 3)


def test_evaluation_reports_lpips_with_the_shared_weights(evaluation: Evaluation) -> None:
    _lpips_weights()  # skips (or fails under CI=true) without ../shared
    saved = evaluation.saved
    assert saved["lpips_backbone"] == "alex"
    assert 0 <= saved["results"]["lpips"] <= 1.5
    assert all(math.isfinite(p["lpips"]) for p in saved["per_image"])


def test_tensorf_baseline_trains_with_the_masks_open(tmp_path: Path) -> None:
    _, run_dir = train_tiny(tmp_path, method="tensorf-vm", iters=ITERS, extra=["--log-every", "5"])
    records = _metrics(run_dir)
    assert records[-1] == {**records[-1], "event": "done", "step": ITERS}
    assert all(r["f_density"] == 1.0 and r["f_color"] == 1.0 for r in records[:-1])
    assert run_dir.parent.name == "tensorf-vm"
    assert list_checkpoints(run_dir / "checkpoints")


def test_same_timestamp_gives_distinct_run_directories(tmp_path: Path) -> None:
    extra = ["--timestamp", "fixed"]
    first = Trainer(tiny_trainer_config(tmp_path, iters=ITERS, extra=extra)).run_dir
    second = Trainer(tiny_trainer_config(tmp_path, iters=ITERS, extra=extra)).run_dir
    assert first != second
    assert first.name == "fixed" and second.name == "fixed-1"
    assert (first / "config.json").is_file() and (second / "config.json").is_file()
