"""The reference grid operations end to end: ``--pipeline.model.accel.backend reference-grid-ops`` trains the bundled
scene through the plain operations (rfft filters, grid_sample lookups, autograd) and ends where the accelerated path
ends.

Both runs are built by the real CLI parser from the same tiny arguments, the reference one with the backend flag
added. 60 iterations cross two occupancy updates (a low threshold, so they mark cells and the second one shrinks the
box and crops the grid) and two upsamples. Compared: every logged loss, the final parameters, the occupancy grid and
box, and the test-split scores of the two runs reloaded from disk (float32 decoder on both, so a bfloat16 render
cannot make them differ; every fourth test view, since rendering is where the reference path is slowest).

Why the parameter tolerance is looser than the losses': AdamW divides by sqrt(v) + eps (eps 1e-8). Where a
gradient is at that level (appearance in empty space, frequencies the filter removes) it is mostly rounding noise,
and the update follows that noise, so such a value may move a few per cent of one learning-rate step differently in
the two runs. The bulk of the values and the network weights agree to rounding.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

import pytest
import torch

from fourierf_plugin.accel import AcceleratedOps
from fourierf_plugin.engine.checkpoint import load_latest_checkpoint
from fourierf_plugin.engine.evaluation import evaluate
from fourierf_plugin.engine.loading import load_run
from fourierf_plugin.engine.trainer import Trainer
from fourierf_plugin.fields.grid_ops import GridOps
from fourierf_plugin.method_configs import config_registry
from tests.helpers import TINY_FINAL_RESO, TINY_INIT_RESO, train_tiny

pytestmark = pytest.mark.slow
ITERS = 60
LOG_EVERY = 5
SHARED_FLAGS = [
    "--log-every", str(LOG_EVERY),
    "--pipeline.datamanager.rays-per-batch", "128",
    "--pipeline.model.accel.decoder-precision", "float32",
    "--pipeline.model.occupancy-threshold", "2e-5",
    "--pipeline.model.occupancy-update-fractions", "0.4", "0.8",  # steps 24 and 48: both find density
    # The dynamics the tolerances were measured under and in which the second update crops the grid: grid lr 0.02 and
    # the band open at 20 % (the budget rule's grid lr 0.04 and longer ramp leave the tiny scene's box uncropped).
    "--budget-rule", "False", "--optimizer.weight-decay", "0", "--optimizer.lr-decay-ratio", "1.0",
]  # fmt: skip
REFERENCE_FLAGS = ["--pipeline.model.accel.backend", "reference-grid-ops"]
PARSER_FLAGS = ["blender-data", "--test-every", "4"]  # 2 of the 8 test views: the reference renders are the slow part
BACKENDS = ("accelerated", "reference-grid-ops")

LOSS_RTOL = 1e-5
NETWORK_ATOL = 3e-5  # basis and decoder (lr 1e-3; seen: 5e-6)
GRID_ATOL = 1e-3  # a twentieth of one AdamW step at lr_grids 0.02, only where gradients are at eps level (seen: 3e-4)
GRID_BULK_ATOL, GRID_BULK_SHARE = 1e-4, 0.99  # seen: at most 0.3 % of a grid's values beyond 1e-4, most within 1e-6
PSNR_ATOL = 1e-4


@dataclass
class Trained:
    trainer: Trainer
    run_dir: Path
    records: list[dict]
    state: dict
    """The model state of the final checkpoint."""


@pytest.fixture(scope="module")
def runs(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Trained]:
    trained = {}
    for backend in BACKENDS:
        extra = [*SHARED_FLAGS, *(REFERENCE_FLAGS if backend == "reference-grid-ops" else []), *PARSER_FLAGS]
        trainer, run_dir = train_tiny(tmp_path_factory.mktemp(backend), iters=ITERS, extra=extra)
        records = [json.loads(line) for line in (run_dir / "metrics.jsonl").read_text().splitlines()]
        _, state = load_latest_checkpoint(run_dir / "checkpoints")
        assert state["step"] == ITERS
        trained[backend] = Trained(trainer, run_dir, records, state["pipeline"]["model"])
    return trained


def test_the_flag_selects_the_reference_ops_and_lands_in_config_json(runs: dict[str, Trained]) -> None:
    assert type(runs["reference-grid-ops"].trainer.pipeline.model.field.ops) is GridOps
    assert isinstance(runs["accelerated"].trainer.pipeline.model.field.ops, AcceleratedOps)
    for backend, run in runs.items():
        saved = json.loads((run.run_dir / "config.json").read_text())["config"]
        assert saved["pipeline"]["model"]["accel"]["backend"] == backend


def test_both_runs_crossed_the_same_occupancy_updates_and_upsamples(runs: dict[str, Trained]) -> None:
    models = [runs[b].trainer.pipeline.model for b in BACKENDS]
    for model in models:
        assert model.occupancy_steps == [24, 48] and model.upsample_steps == [18, 42]
        assert model.occupancy.active, "the updates marked occupied cells (the march skips empty space)"
        assert model.field.resolution not in (TINY_INIT_RESO, TINY_FINAL_RESO), "the last update cropped the grid"
    accelerated, reference = models
    assert torch.equal(accelerated.aabb, reference.aabb)
    assert not torch.equal(accelerated.aabb, torch.tensor([[-1.5] * 3, [1.5] * 3])), "the box shrank"
    assert accelerated.field.resolution == reference.field.resolution
    assert torch.equal(accelerated.occupancy.cells, reference.occupancy.cells)


def test_every_logged_loss_matches(runs: dict[str, Trained]) -> None:
    logged = {b: [r for r in runs[b].records if "loss" in r] for b in BACKENDS}
    assert [r["step"] for r in logged["reference-grid-ops"]] == list(range(LOG_EVERY, ITERS + 1, LOG_EVERY))
    assert [r["step"] for r in logged["accelerated"]] == [r["step"] for r in logged["reference-grid-ops"]]
    for ours, theirs in zip(logged["reference-grid-ops"], logged["accelerated"], strict=True):
        for key in ("loss", "psnr", "rays"):
            assert ours[key] == pytest.approx(theirs[key], rel=LOSS_RTOL), (ours["step"], key)


def test_final_parameters_match(runs: dict[str, Trained]) -> None:
    ours, theirs = runs["reference-grid-ops"].state, runs["accelerated"].state
    assert ours.keys() == theirs.keys()
    for name, value in ours.items():
        other = theirs[name]
        assert value.shape == other.shape, name
        if not value.is_floating_point():
            assert torch.equal(value, other), name
        elif "_grid." in name:
            torch.testing.assert_close(value, other, rtol=0, atol=GRID_ATOL, msg=name)
            share = float(((value - other).abs() <= GRID_BULK_ATOL).float().mean())
            assert share >= GRID_BULK_SHARE, f"{name}: only {share:.2%} of the values within {GRID_BULK_ATOL}"
        else:
            torch.testing.assert_close(value, other, rtol=0, atol=NETWORK_ATOL, msg=name)


def test_reloaded_runs_score_the_same_on_the_test_split(runs: dict[str, Trained]) -> None:
    reports = {}
    for backend, run in runs.items():
        loaded = load_run(run.run_dir / "config.json", config_registry(), device="cpu")
        expected = GridOps if backend == "reference-grid-ops" else AcceleratedOps
        assert type(loaded.pipeline.model.field.ops) is expected, "config.json rebuilds the run's backend"
        reports[backend] = evaluate(loaded, "test")
    ours, theirs = reports["reference-grid-ops"], reports["accelerated"]
    assert ours["view_ids"] == theirs["view_ids"] == [0, 4]
    assert ours["results"]["psnr"] == pytest.approx(theirs["results"]["psnr"], abs=PSNR_ATOL)
    for a, b in zip(ours["per_image"], theirs["per_image"], strict=True):
        assert a["psnr"] == pytest.approx(b["psnr"], abs=PSNR_ATOL), a["name"]
        assert a["ssim"] == pytest.approx(b["ssim"], abs=PSNR_ATOL), a["name"]
