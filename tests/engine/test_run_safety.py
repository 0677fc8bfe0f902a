"""A run is trained by one process at a time, resumes past a log line cut short, and stops with a clear message when
its loss diverges, keeping the last finite checkpoint."""

from __future__ import annotations

import json
import subprocess
import sys
import time
from pathlib import Path

import pytest
import torch

from fourierf_plugin.engine.checkpoint import list_checkpoints, load_checkpoint
from fourierf_plugin.engine.run_dir import LOCK_NAME, lock_run
from fourierf_plugin.engine.trainer import Trainer
from fourierf_plugin.scripts.train import build_config, parse_args
from fourierf_plugin.utils.errors import UserError
from tests.helpers import REPO_ROOT, train_tiny


def resumed(run_dir: Path) -> Trainer:
    config, _ = build_config(parse_args(["fourierf-vm", "--load-dir", str(run_dir)]))
    return Trainer(config)


def test_a_second_writer_is_refused_by_pid_and_a_dead_ones_lock_is_taken_over(tmp_path: Path, capsys) -> None:
    holder = subprocess.Popen(
        [sys.executable, "-c", f"from fourierf_plugin.engine.run_dir import lock_run; lock_run({str(tmp_path)!r}); "
         "print('held', flush=True); import time; time.sleep(60)"],
        cwd=REPO_ROOT, stdout=subprocess.PIPE, text=True,
    )  # fmt: skip
    try:
        assert holder.stdout is not None and holder.stdout.readline().strip() == "held"
        with pytest.raises(UserError) as info:
            lock_run(tmp_path)
        assert f"process {holder.pid}" in info.value.problem and f"kill {holder.pid}" in (info.value.fix or "")
    finally:
        holder.kill()
        holder.wait()
    lock = lock_run(tmp_path)  # the holder died: its lock file names it, and the lock is free
    try:
        assert f"{holder.pid}" in capsys.readouterr().err
    finally:
        lock.release()
    assert not (tmp_path / LOCK_NAME).exists()


def test_resume_of_a_run_still_training_is_refused_before_anything_is_written(tmp_path: Path) -> None:
    _, run_dir = train_tiny(tmp_path, iters=6)
    config_before = (run_dir / "config.json").read_bytes()
    holder = subprocess.Popen(
        [sys.executable, "-c", f"from fourierf_plugin.engine.run_dir import lock_run; lock_run({str(run_dir)!r}); "
         "print('held', flush=True); import time; time.sleep(60)"],
        cwd=REPO_ROOT, stdout=subprocess.PIPE, text=True,
    )  # fmt: skip
    try:
        assert holder.stdout is not None and holder.stdout.readline().strip() == "held"
        with pytest.raises(UserError, match=f"process {holder.pid}"):
            resumed(run_dir)
    finally:
        holder.kill()
        holder.wait()
    assert (run_dir / "config.json").read_bytes() == config_before


def test_a_torn_last_line_of_the_log_is_dropped_and_the_run_resumes(tmp_path: Path, capsys) -> None:
    _, run_dir = train_tiny(tmp_path, iters=6, extra=["--log-every", "2", "--steps-per-save", "2"])
    metrics = run_dir / "metrics.jsonl"
    lines = metrics.read_text().splitlines()
    metrics.write_text("\n".join(lines[:-1]) + '\n{"step": 6, "loss": 0.0')  # the power cut mid-line
    (run_dir / "checkpoints" / "step-000000006.ckpt").unlink()  # resume from step 4
    trainer = resumed(run_dir)
    trainer.train()
    assert "cut short" in capsys.readouterr().err
    records = [json.loads(line) for line in metrics.read_text().splitlines()]
    assert [r["step"] for r in records if "loss" in r] == [2, 4, 6]


def test_a_diverging_loss_stops_the_run_and_keeps_the_last_finite_checkpoint(tmp_path: Path) -> None:
    started = time.perf_counter()
    with pytest.raises(UserError) as info:
        train_tiny(
            tmp_path, iters=40, extra=["--optimizer.lr-grids", "1e30", "--steps-per-save", "1", "--log-every", "1"]
        )
    assert time.perf_counter() - started < 120
    problem, fix = info.value.problem, info.value.fix or ""
    assert "at step" in problem and "last finite" in problem and "--optimizer.lr-grids 1e+30" in fix
    (run_dir,) = [p.parent for p in tmp_path.rglob("metrics.jsonl")]
    for path in list_checkpoints(run_dir / "checkpoints"):
        state = load_checkpoint(path)["pipeline"]
        assert all(torch.isfinite(v).all() for v in state.values() if torch.is_tensor(v) and v.is_floating_point())
    assert not (run_dir / LOCK_NAME).exists(), "a stopped run leaves its folder free"
