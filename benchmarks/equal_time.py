"""The equal-time stage: each method given the same wall time on each scene, as a user with T minutes would run it.

A point is (scene, method, budget): ``fourierf-train METHOD --time-budget B --threads 1`` with no size flag (the run
is sized for the scene and the machine, the short-run rules applying as to any run), then ``fourierf-eval`` on the
test views. One row a point in ``results/equal_time/results.jsonl``; a budget too short for a method's fewest
iterations is a row that says so, not a failure.
"""

from __future__ import annotations

import re
import time
from collections.abc import Collection, Sequence
from dataclasses import dataclass
from pathlib import Path

from harness import Run, Suite, cpu_and_cores, done_record, read_metrics, train_and_eval, train_command

from fourierf_plugin.method_configs.time_budget import parse_duration

THREADS = 1
"""One thread a run: a CPU run is then bit-reproducible, and two run side by side on two cores."""
TOO_SHORT = re.compile(r"--time-budget \S+ is too short[^\n]*")
ESTIMATE = re.compile(r"~([0-9.e+-]+) s per iteration")
"""The trainer's own estimate in its too-short message: a method too slow for every budget still gets a speed."""


@dataclass(frozen=True)
class Point:
    scene: str
    method: str
    budget: str

    @property
    def key(self) -> str:
        return f"{self.scene}/{self.method}/{self.budget}"

    def run(self, suite: Suite) -> Run:
        return Run(self.method, 0, suite.equal_time["seed"], "equal-time", self.budget)


def plan(
    suite: Suite, scenes: Sequence[str], budgets: Sequence[str], known: Collection[str],
    only: Sequence[str] | None = None,
) -> tuple[list[Point], list[str]]:
    """The points of the suite's methods (or ``only`` those) on ``scenes`` at ``budgets``, longest budget first (two
    jobs at once end on short runs), and a line for each method the registry does not know (skipped)."""
    wanted = only or suite.equal_time["methods"]
    methods = [m for m in wanted if m in known]
    skipped = [
        f"skipped {m}: no such method in this install's registry (known: {', '.join(sorted(known))})"
        for m in wanted
        if m not in known
    ]
    longest_first = sorted(budgets, key=parse_duration, reverse=True)
    return [Point(scene, m, b) for b in longest_first for scene in scenes for m in methods], skipped


def point_command(point: Point, suite: Suite, data: Path, work: Path) -> list[str]:
    """The training command of a point (what ``execute`` runs, without running it)."""
    run, scene = point.run(suite), suite.scenes[point.scene]
    parser = suite.parser_args(point.scene, suite.equal_time["protocol"])
    return train_command(run, data / scene["path"], work / point.scene / "runs", parser, threads=THREADS)


def too_short(log: Path) -> str | None:
    """The train CLI's "--time-budget ... is too short" line in a failed run's log, or None (another failure)."""
    found = TOO_SHORT.search(log.read_text(errors="replace")) if log.is_file() else None
    return found.group(0) if found else None


def execute(point: Point, suite: Suite, data: Path, work: Path, lpips: Path, jobs: int) -> dict:
    """Train and evaluate one point; its row (planned and actual training seconds from the run's metrics)."""
    started, run = time.perf_counter(), point.run(suite)
    row = {
        "scene": point.scene, "method": point.method, "budget": point.budget,
        "budget_seconds": parse_duration(point.budget), "threads": THREADS, "jobs": jobs, "machine": cpu_and_cores(),
    }  # fmt: skip
    parser = suite.parser_args(point.scene, suite.equal_time["protocol"])
    scene_data, scene_work = data / suite.scenes[point.scene]["path"], work / point.scene
    try:
        trained = train_and_eval(run, scene_data, parser, scene_work, lpips, point.scene, threads=THREADS)
    except RuntimeError:
        message = too_short(scene_work / f"{run.key}.train.log")
        if message is None:
            raise
        estimate = ESTIMATE.search(message)
        row |= {"estimated_seconds_per_iteration": float(estimate.group(1))} if estimate else {}
        return row | {"too_short": message, "seconds": time.perf_counter() - started}
    done = done_record(read_metrics(Path(trained["run_dir"]) / "metrics.jsonl")) or {}
    iterations, seconds = int(done["step"]), float(done["train_seconds"])
    return row | {
        "planned_seconds": done.get("planned_train_seconds"), "trained_seconds": seconds, "iterations": iterations,
        "seconds_per_iteration": seconds / iterations, "psnr": trained["psnr"], "ssim": trained["ssim"],
        "lpips": trained["lpips"], "train_threads": trained["train_threads"],
        "train_view_ids": trained["train_view_ids"], "run_dir": trained["run_dir"],
        "seconds": time.perf_counter() - started,
    }  # fmt: skip


def known_methods() -> set[str]:
    """The method names this install's registry knows (presets and plugins)."""
    from fourierf_plugin.method_configs.registry import all_methods

    return set(all_methods)
