"""One bench run: ``fourierf-train`` in a child process (wall time, peak RSS), then every planned checkpoint evaluated.

Why a child process for training: its wall time and peak memory are the run's own (read from the child's rusage),
and nothing the coordinator or an earlier run left in memory is counted. Evaluation runs in the worker process
itself (no interpreter start-up per checkpoint), after training, so it never disturbs the timing.
"""

from __future__ import annotations

import contextlib
import os
import re
import shutil
import subprocess
import sys
import time
import traceback
from dataclasses import dataclass, field
from pathlib import Path
from typing import Literal

import torch

from fourierf_plugin.bench import phases as ph
from fourierf_plugin.bench.sweep import RunSpec
from fourierf_plugin.engine.checkpoint import checkpoint_name
from fourierf_plugin.engine.evaluation import evaluate
from fourierf_plugin.engine.loading import load_run
from fourierf_plugin.method_configs import config_registry
from fourierf_plugin.utils.console import write_json
from fourierf_plugin.utils.lpips import LPIPS, default_lpips_weights

SceneKind = Literal["blender", "llff", "nerfstudio", "colmap"]


@dataclass(frozen=True)
class Scene:
    """The scene every run of a bench trains on; ``parser_args`` are the parser flags other than --downscale."""

    data: Path
    kind: SceneKind
    parser_args: tuple[str, ...] = ()

    @property
    def parser_command(self) -> str:
        return f"{self.kind}-data"

    def parser_flags(self, downscale: int | None) -> list[str]:
        flags = [self.parser_command]
        if downscale is not None:
            flags += ["--downscale", str(downscale)]
        return flags + list(self.parser_args)


@dataclass(frozen=True)
class RunTask:
    """Everything a worker (local or remote) needs for one run; plain data, so it pickles anywhere."""

    spec: RunSpec
    scene: Scene
    out_dir: Path
    threads: int | None = None
    device: str = "auto"
    lpips_weights: Path | None = None
    keep_checkpoints: bool = False
    train_args: tuple[str, ...] = ()
    """fourierf-train flags for this run beyond the knobs (the same for every run of a bench)."""

    @property
    def runs_dir(self) -> Path:
        return self.out_dir / "runs"

    @property
    def log_dir(self) -> Path:
        return self.out_dir / "logs"


@dataclass
class RunResult:
    key: str
    ok: bool
    rows: list[dict] = field(default_factory=list)
    record: dict = field(default_factory=dict)
    error: str | None = None


def train_command(task: RunTask) -> list[str]:
    spec = task.spec
    script = Path(sys.executable).parent / "fourierf-train"
    launcher = [str(script)] if script.is_file() else [sys.executable, "-m", "fourierf_plugin.scripts.train"]
    cmd = [*launcher, *spec.train_args()]
    cmd += ["--data", str(task.scene.data), "--output-dir", str(task.runs_dir), "--timestamp", spec.key]
    cmd += ["--device", task.device]
    if task.threads is not None:
        cmd += ["--threads", str(task.threads)]
    if spec.profile_phases:
        cmd += ["--profile-phases", "True"]
    return cmd + list(task.train_args) + task.scene.parser_flags(spec.downscale)


def run_timed(cmd: list[str], log: Path, env: dict[str, str] | None = None) -> tuple[float, float, int]:
    """Wall seconds, peak RSS (GB) and exit code of one child process, its output going to ``log``."""
    log.parent.mkdir(parents=True, exist_ok=True)
    start = time.perf_counter()
    with log.open("w") as fh:
        fh.write(" ".join(cmd) + "\n\n")
        fh.flush()
        proc = subprocess.Popen(cmd, stdout=fh, stderr=subprocess.STDOUT, env=env)
        _, status, usage = os.wait4(proc.pid, 0)
    return time.perf_counter() - start, usage.ru_maxrss / 1024**2, os.waitstatus_to_exitcode(status)


def _child_env(threads: int | None) -> dict[str, str]:
    env = dict(os.environ)
    if threads is not None:
        env["OMP_NUM_THREADS"] = env["MKL_NUM_THREADS"] = str(threads)
    return env


def clear_previous(task: RunTask) -> None:
    """Remove what an interrupted attempt at this run left behind (the bench owns its folder)."""
    pattern = re.compile(re.escape(task.spec.key) + r"(-\d+)?$")
    for folder in task.runs_dir.glob(f"*/{task.spec.method}/{task.spec.key}*"):
        if folder.is_dir() and pattern.match(folder.name):
            shutil.rmtree(folder, ignore_errors=True)


def find_run_dir(task: RunTask) -> Path:
    found = sorted(task.runs_dir.glob(f"*/{task.spec.method}/{task.spec.key}/config.json"))
    if not found:
        raise RuntimeError(f"training finished but no run directory for {task.spec.key} under {task.runs_dir}")
    return found[0].parent


def evaluate_checkpoints(task: RunTask, run_dir: Path, steps: tuple[int, ...], log: Path) -> dict[int, dict]:
    """The evaluation report of each planned step (no images written), its console output going to ``log``."""
    if task.threads is not None:
        torch.set_num_threads(task.threads)
    weights = task.lpips_weights or default_lpips_weights()
    lpips = LPIPS(weights) if weights is not None else None
    reports = {}
    with log.open("w") as fh, contextlib.redirect_stdout(fh), contextlib.redirect_stderr(fh):
        for step in steps:
            ckpt = run_dir / "checkpoints" / checkpoint_name(step)
            if not ckpt.is_file():
                raise RuntimeError(f"no checkpoint for step {step} in {run_dir / 'checkpoints'}")
            started = time.perf_counter()
            run = load_run(run_dir / "config.json", config_registry(), ckpt, task.device)
            report = evaluate(run, "test", lpips.to(run.device) if lpips is not None else None)
            write_json(run_dir / "bench_eval" / f"step-{step:09d}.json", report)
            report["bench_eval_seconds"] = time.perf_counter() - started
            reports[step] = report
    return reports


def prune_checkpoints(run_dir: Path, keep_step: int) -> None:
    """Keep only the final checkpoint once every planned step is evaluated (a sweep would otherwise fill disks)."""
    for ckpt in (run_dir / "checkpoints").glob("step-*.ckpt"):
        if ckpt.name != checkpoint_name(keep_step):
            ckpt.unlink(missing_ok=True)


def measurement_rows(spec: RunSpec, reports: dict[int, dict], records: list[dict], record: dict) -> list[dict]:
    """One CSV row per evaluated step: the run's knobs, how far and how long it had trained, and the metrics."""
    elapsed = ph.elapsed_by_step(records)
    base = {
        "key": spec.key,
        "method": spec.method,
        **spec.knobs(),
        "init_voxels": spec.init_voxels,
        "grid_side": round(spec.grid_voxels ** (1 / 3), 2),
        "delta_per_iter": spec.delta_per_iteration(),
        "seed": spec.seed,
        "eval_points": spec.eval_points,
        "profiled": record.get("profiled", False),
        "train_seconds_total": record.get("train_seconds"),
        "wall_seconds": record.get("wall_seconds"),
        "peak_rss_gb": record.get("peak_rss_gb"),
        "run_dir": record.get("run_dir"),
    }
    rows = []
    for step, report in sorted(reports.items()):
        results = report["results"]
        rows.append(
            base
            | {
                "step": step,
                "fraction": step / spec.iters,
                "train_seconds_at_step": elapsed.get(step),
                "psnr": results.get("psnr"),
                "ssim": results.get("ssim"),
                "lpips": results.get("lpips"),
                "test_views": report.get("num_views"),
                "eval_seconds": report.get("bench_eval_seconds"),
            }
        )
    return rows


def execute_run(task: RunTask) -> RunResult:
    """Train, evaluate and summarise one run; failures come back as a result (a sweep goes on without it)."""
    spec = task.spec
    train_log = task.log_dir / f"{spec.key}.train.log"
    try:
        clear_previous(task)
        wall, rss, code = run_timed(train_command(task), train_log, _child_env(task.threads))
        if code != 0:
            return RunResult(spec.key, False, error=f"training exited with {code}; see {train_log}")
        run_dir = find_run_dir(task)
        records = ph.read_metrics(run_dir / "metrics.jsonl")
        done = ph.done_record(records)
        record = {
            "key": spec.key,
            "spec": spec.as_dict(),
            "wall_seconds": wall,
            "train_seconds": done.get("train_seconds") if done else None,
            "peak_rss_gb": rss,
            "profiled": spec.profile_phases,
            "phases_total": ph.phases_total(records),
            "phases_final": ph.phases_final(records, spec.iters),
            "run_dir": str(run_dir),
            "train_log": str(train_log),
        }
        reports = evaluate_checkpoints(task, run_dir, spec.eval_steps(), task.log_dir / f"{spec.key}.eval.log")
        if not task.keep_checkpoints:
            prune_checkpoints(run_dir, spec.iters)
        return RunResult(spec.key, True, measurement_rows(spec, reports, records, record), record)
    except Exception as err:  # a worker must report, not die: the coordinator lists failures at the end
        detail = "".join(traceback.format_exception_only(type(err), err)).strip()
        return RunResult(spec.key, False, error=f"{detail} (logs in {task.log_dir})")
