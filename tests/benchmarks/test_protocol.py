"""benchmarks/harness.py with the child processes faked: ``threads`` reaches both the training and every
evaluation, so jobs run side by side never oversubscribe the cores (an evaluation without it takes every core)."""

from __future__ import annotations

import json
from pathlib import Path

import harness as protocol
import pytest

from fourierf_plugin.utils.console import cpu_threads_note


@pytest.fixture
def commands(monkeypatch: pytest.MonkeyPatch) -> list[list[str]]:
    """Every command the harness launches; training writes views.json, evaluation its eval.json."""
    launched: list[list[str]] = []

    def fake_run_timed(cmd: list[str], log: Path, env: dict | None = None) -> tuple[float, float, int]:
        launched.append(cmd)
        if cmd[0].endswith("fourierf-train"):
            threads = _threads(cmd) or "2"  # the trainer's log line; torch's default on a 2-core machine
            log.write_text(f"device cpu ({cpu_threads_note(int(threads))}), grid [16, 16, 16],\n")
            run_dir = Path(cmd[cmd.index("--output-dir") + 1]) / "lego" / cmd[1] / cmd[cmd.index("--timestamp") + 1]
            run_dir.mkdir(parents=True)
            (run_dir / "views.json").write_text(json.dumps({"train_view_ids": [0, 1]}))
        else:
            report = {
                "results": {"psnr": 20.0, "ssim": 0.8, "lpips": 0.1}, "num_views": 2, "view_ids": [2, 3],
                "timings": {"render_seconds_total": 1.0},
            }  # fmt: skip
            Path(cmd[cmd.index("--output-path") + 1]).write_text(json.dumps(report))
        return 1.0, 0.5, 0

    monkeypatch.setattr(protocol, "run_timed", fake_run_timed)
    return launched


def _threads(cmd: list[str]) -> str | None:
    return cmd[cmd.index("--threads") + 1] if "--threads" in cmd else None


def test_threads_reach_the_training_and_every_evaluation(commands: list[list[str]], tmp_path: Path) -> None:
    run = protocol.Run("fourierf-vm", 10, 1, "tiny")
    row = protocol.train_and_eval(run, tmp_path / "data", ["blender-data"], tmp_path, tmp_path / "w.pth", threads=1)
    row |= protocol.evaluate(Path(row["run_dir"]), run.key, tmp_path, tmp_path / "w.pth", split="val", threads=1)
    assert [_threads(c) for c in commands] == ["1", "1", "1"]
    assert (row["psnr"], row["val_psnr"], row["val_view_ids"]) == (20.0, 20.0, [2, 3])
    assert row["machine"] == protocol.cpu_and_cores()  # rows span machines: each says where it ran
    assert row["train_threads"] == 1  # a rerun must use as many: the thread count sets the order of float sums


def test_without_threads_no_flag_is_passed(commands: list[list[str]], tmp_path: Path) -> None:
    run = protocol.Run("tensorf-vm", 10, 1, "tiny")
    row = protocol.train_and_eval(run, tmp_path / "data", ["blender-data"], tmp_path, tmp_path / "w.pth")
    assert [_threads(c) for c in commands] == [None, None]
    assert row["train_threads"] == 2  # what the trainer reported, not what was asked


def test_threads_used_reads_the_trainers_line_or_none(tmp_path: Path) -> None:
    log = tmp_path / "train.log"
    assert protocol.threads_used(log) is None  # no log at all
    log.write_text("loading data\nstep 10/10\n")
    assert protocol.threads_used(log) is None
    log.write_text(f"device cpu ({cpu_threads_note(16)}), grid [64, 64, 64]\n".replace(" ", "\n", 3))  # wrapped
    assert protocol.threads_used(log) == 16


def test_revived_batches_reads_the_last_logged_count_or_none(tmp_path: Path) -> None:
    metrics = tmp_path / "metrics.jsonl"
    assert protocol.revived_batches(metrics) is None  # no log
    lines = [{"step": 40, "loss": 0.1}, {"step": 80, "revived_batches": 3.0}, {"step": 120, "revived_batches": 5.0}]
    metrics.write_text("".join(json.dumps(r) + "\n" for r in [*lines, {"event": "done", "step": 120}]))
    assert protocol.revived_batches(metrics) == 5  # the count so far at the last logged step
    metrics.write_text(json.dumps(lines[0]) + "\n")
    assert protocol.revived_batches(metrics) is None  # a field that cannot revive, or a log from before the count
    metrics.write_text("{not json\n")
    assert protocol.revived_batches(metrics) is None
