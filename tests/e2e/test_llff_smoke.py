"""End to end on the shared fern: a 3-view fourierf-vm run in NDC on a tiny grid, checkpointed, reloaded, rendered.

``--downscale 16`` (no images_16/ folder: the parser resizes a larger one to 252x189) keeps the CPU run and the
hold-out render to seconds.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass
from pathlib import Path

import pytest
import torch

from fourierf_plugin.engine.checkpoint import list_checkpoints
from fourierf_plugin.engine.loading import load_run
from fourierf_plugin.engine.trainer import Trainer
from fourierf_plugin.method_configs import config_registry
from fourierf_plugin.scripts.train import build_config, parse_args
from fourierf_plugin.utils.metrics import psnr, ssim
from tests.conftest import require_shared
from tests.helpers import TINY_FLAGS

pytestmark = pytest.mark.slow
ITERS = 20
WIDTH, HEIGHT = 252, 189


@dataclass
class FernRun:
    trainer: Trainer
    run_dir: Path
    records: list[dict]


@pytest.fixture(scope="module")
def fern_run(tmp_path_factory) -> FernRun:
    fern = require_shared("data", "llff", "fern")
    args = [
        "fourierf-vm",
        "--data",
        str(fern),
        "--output-dir",
        str(tmp_path_factory.mktemp("out")),
        "--max-num-iterations",
        str(ITERS),
        "--log-every",
        "1",
        *TINY_FLAGS,
        "llff-data",
        "--num-views",
        "3",
        "--downscale",
        "16",
    ]
    trainer = Trainer(build_config(parse_args(args))[0])
    run_dir = trainer.train()
    records = [json.loads(line) for line in (run_dir / "metrics.jsonl").read_text().splitlines()]
    return FernRun(trainer, run_dir, records)


def test_run_records_views_config_and_checkpoint(fern_run: FernRun) -> None:
    d = fern_run.run_dir
    assert d.parent.name == "fourierf-vm" and d.parent.parent.name == "fern"
    views = json.loads((d / "views.json").read_text())
    assert views["scene"] == "fern"
    assert views["train_view_ids"] == [1, 10, 19]
    assert views["train_image_names"] == ["image001", "image010", "image019"]
    saved = json.loads((d / "config.json").read_text())["config"]
    assert saved["scene_preset"] == "real"
    effects = saved["pipeline"]["effects"]
    assert (effects["ray_space"], effects["background"], effects["occlusion_regularization"]) == ("ndc", "none", True)
    checkpoints = list_checkpoints(d / "checkpoints")
    assert checkpoints and checkpoints[-1].name == f"step-{ITERS:09d}.ckpt"


def test_training_metrics_are_finite(fern_run: FernRun) -> None:
    steps = [r for r in fern_run.records if "loss" in r]
    assert [r["step"] for r in steps] == list(range(1, ITERS + 1))
    for r in steps:
        assert math.isfinite(r["loss"]) and math.isfinite(r["psnr"]) and math.isfinite(r["occlusion"])
    assert steps[0]["f_density"] == pytest.approx(0.01), "the real-scene curriculum starts at f0 = 0.01"
    assert fern_run.records[-1]["event"] == "done"


def test_reloaded_run_renders_a_hold_out_view(fern_run: FernRun) -> None:
    """The run rebuilt from config.json + checkpoint renders hold-out view 0 with finite metrics on black."""
    run = load_run(fern_run.run_dir / "config.json", config_registry(), device="cpu")
    assert run.step == ITERS and run.pipeline.model.effects.ray_space == "ndc"
    trained = fern_run.trainer.pipeline.model.state_dict()
    for name, value in run.pipeline.model.state_dict().items():
        torch.testing.assert_close(value, trained[name], rtol=0, atol=0, msg=name)
    view = next(run.pipeline.render_views("test", run.step))
    assert view.view.view_id == 0 and view.view.name == "image000"
    assert tuple(view.rgb.shape) == (HEIGHT, WIDTH, 3) and tuple(view.depth.shape) == (HEIGHT, WIDTH)
    for image in (view.rgb, view.depth, view.accumulation):
        assert bool(torch.isfinite(image).all())
    assert float(view.rgb.min()) >= 0.0 and float(view.rgb.max()) <= 1.0
    p, s = psnr(view.rgb, view.target), ssim(view.rgb, view.target)
    assert math.isfinite(p) and p > 0 and math.isfinite(s)
