"""``--vis tensorboard``: event files that TensorBoard's own reader loads, with the run's scalars and renders, written
without changing training; a resumed run does not log a step twice; a missing package is one clear error."""

from __future__ import annotations

import builtins
import json
from pathlib import Path

import pytest
import torch

from fourierf_plugin.engine.checkpoint import list_checkpoints, load_latest_checkpoint
from fourierf_plugin.engine.trainer import Trainer
from fourierf_plugin.scripts.observers import build_observers
from fourierf_plugin.scripts.train import build_config, parse_args
from fourierf_plugin.utils.errors import UserError
from tests.conftest import require_module
from tests.helpers import TINY_IMAGE_SIZE, tiny_trainer_config

pytestmark = pytest.mark.slow

ITERS = 30
LOG_EVERY = 10
IMAGE_EVERY = 15
FLAGS = ["--log-every", str(LOG_EVERY), "--vis", "tensorboard", "--vis-image-every", str(IMAGE_EVERY)]


def _events(run_dir: Path):
    accumulator = require_module(
        "tensorboard.backend.event_processing.event_accumulator", "--vis tensorboard needs tensorboard"
    )
    events = accumulator.EventAccumulator(str(run_dir / "tensorboard"), size_guidance={"scalars": 0, "images": 0})
    events.Reload()
    return events


def _train(tmp_path: Path, extra: list[str]) -> tuple[Trainer, Path]:
    config = tiny_trainer_config(tmp_path, iters=ITERS, extra=extra)
    trainer = Trainer(config, build_observers(config))
    return trainer, trainer.train()


def _records(run_dir: Path) -> list[dict]:
    lines = (run_dir / "metrics.jsonl").read_text().splitlines()
    return [r for r in map(json.loads, lines) if "event" not in r]


def test_event_files_hold_the_logged_scalars_and_the_renders(tmp_path: Path) -> None:
    require_module("tensorboard", "--vis tensorboard needs tensorboard (pip install '.[tensorboard]')")
    _, run_dir = _train(tmp_path, FLAGS)
    events = _events(run_dir)
    tags = events.Tags()
    records = _records(run_dir)
    assert [r["step"] for r in records] == [10, 20, 30]
    for tag, key in (("train/loss", "loss"), ("train/psnr", "psnr"), ("schedule/f_density", "f_density")):
        scalars = events.Scalars(tag)
        assert [s.step for s in scalars] == [r["step"] for r in records]
        for s, r in zip(scalars, records, strict=True):
            assert s.value == pytest.approx(r[key], rel=1e-6, abs=1e-7)  # TensorBoard keeps float32
    assert "schedule/grid_voxels" in tags["scalars"]
    for label in ("train", "held_out"):
        images = events.Images(f"{label}/rgb_vs_target")
        assert [i.step for i in images] == [15, 30]
        height, width = TINY_IMAGE_SIZE
        assert (images[-1].height, images[-1].width) == (height, 2 * width)  # render | target
        assert [i.step for i in events.Images(f"{label}/depth")] == [15, 30]


def test_logging_does_not_change_training(tmp_path: Path) -> None:
    require_module("tensorboard", "--vis tensorboard needs tensorboard (pip install '.[tensorboard]')")
    _, plain = _train(tmp_path / "plain", ["--log-every", str(LOG_EVERY)])
    _, logged = _train(tmp_path / "logged", FLAGS)
    a = load_latest_checkpoint(plain / "checkpoints")[1]["pipeline"]
    b = load_latest_checkpoint(logged / "checkpoints")[1]["pipeline"]
    assert a.keys() == b.keys()
    for key in a:
        if isinstance(a[key], torch.Tensor):
            assert torch.equal(a[key], b[key]), key
    assert [r["loss"] for r in _records(plain)] == [r["loss"] for r in _records(logged)]


def test_a_resumed_run_logs_no_step_twice(tmp_path: Path) -> None:
    require_module("tensorboard", "--vis tensorboard needs tensorboard (pip install '.[tensorboard]')")
    _, run_dir = _train(tmp_path, [*FLAGS, "--steps-per-save", "20"])
    latest = list_checkpoints(run_dir / "checkpoints")[-1]
    latest.unlink()  # as if the run had stopped after its step-20 checkpoint, with steps 21..30 already logged
    config, _ = build_config(parse_args(["fourierf-vm", "--load-dir", str(run_dir)]))
    Trainer(config, build_observers(config)).train()
    events = _events(run_dir)
    assert [s.step for s in events.Scalars("train/loss")] == [10, 20, 30]
    assert [i.step for i in events.Images("train/rgb_vs_target")] == [15, 30]


def test_a_missing_tensorboard_package_names_the_extra(monkeypatch: pytest.MonkeyPatch) -> None:
    real_import = builtins.__import__

    def without_tensorboard(name, *args, **kwargs):
        if name.startswith("torch.utils.tensorboard") or name.startswith("tensorboard"):
            raise ImportError(f"No module named {name!r}")
        return real_import(name, *args, **kwargs)

    monkeypatch.setattr(builtins, "__import__", without_tensorboard)
    from fourierf_plugin.vis.tensorboard_writer import TensorBoardObserver

    with pytest.raises(UserError) as info:
        TensorBoardObserver(image_every=10)
    assert "fourierf[tensorboard]" in (info.value.fix or "")
