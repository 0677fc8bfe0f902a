"""The equal-time and equal-iterations stages (``run.py equal-time`` / ``equal-iterations``): each method given the
same wall time (``--time-budget``) or iterations ("800it") on each scene, as a user would run it with no size flag; a
budget too short for a method's fewest iterations is a row that says so, not a failure."""

from __future__ import annotations

import re
import time
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

from harness import Run, Suite, cpu_and_cores, done_record, read_metrics, train_and_eval, train_command

from fourierf_plugin.method_configs.time_budget import parse_duration

THREADS = 1
"""One thread a run: a CPU run is then bit-reproducible, and two run side by side on two cores."""
TOO_SHORT = re.compile(r"--time-budget \S+ is too short[^\n]*")
ESTIMATE = re.compile(r"~([0-9.e+-]+) s per iteration")
"""The trainer's own estimate in its too-short message: a method too slow for every budget still gets a speed."""
ITERATION_BUDGET = re.compile(r"([1-9][0-9]*)it")


def budget_iterations(budget: str) -> int | None:
    """The iterations of a budget such as "800it", or None (a wall-time budget such as "3m")."""
    found = ITERATION_BUDGET.fullmatch(budget)
    return int(found.group(1)) if found else None


@dataclass(frozen=True)
class IterationRun(Run):
    """A run of ``iters`` iterations sized as the default CPU run (no grid or ray flag), keyed by its point's name
    (a variant trains its method under its own key)."""

    name: str = ""

    @property
    def key(self) -> str:
        return f"{self.name or self.method}_{self.views}_{self.iters}it_s{self.seed}"

    def sizes(self) -> list[str]:
        return ["--max-num-iterations", str(self.iters)]


def variants(suite: Suite) -> dict[str, dict]:
    """The equal-iterations variants: a name → its method, flags and the scenes it runs on."""
    return suite.equal_time["iterations"].get("variants", {})


@dataclass(frozen=True)
class Point:
    scene: str
    method: str
    budget: str

    @property
    def key(self) -> str:
        return f"{self.scene}/{self.method}/{self.budget}"

    def run(self, suite: Suite) -> Run:
        seed, iterations = suite.equal_time["seed"], budget_iterations(self.budget)
        if iterations is None:
            return Run(self.method, 0, seed, "equal-time", self.budget)
        method = variants(suite).get(self.method, {}).get("method", self.method)
        return IterationRun(method, iterations, seed, "equal-iterations", name=self.method)

    def flags(self, suite: Suite) -> list[str]:
        """A variant's own flags (none for a plain method)."""
        return list(variants(suite).get(self.method, {}).get("flags", []))


def plan(suite: Suite, scenes: Sequence[str], budgets: Sequence[str], only: Sequence[str] | None = None) -> list[Point]:
    """The points of the suite's methods (or ``only`` those) on ``scenes`` at ``budgets``, longest budget first (two
    jobs at once end on short runs)."""
    longest_first = sorted(budgets, key=parse_duration, reverse=True)
    methods = only or suite.equal_time["methods"]
    return [Point(scene, m, b) for b in longest_first for scene in scenes for m in methods]


def iteration_plan(
    suite: Suite, scenes: Sequence[str], only: Sequence[str] | None = None, budget: str | None = None
) -> list[Point]:
    """The equal-iterations points at ``budget`` (the suite's by default) in the suite's method order (slowest first,
    so two jobs at once end on short runs), a variant only on its scenes."""
    stage, found = suite.equal_time["iterations"], variants(suite)
    return [
        Point(scene, m, budget or stage["budget"])
        for m in only or stage["methods"]
        for scene in scenes
        if scene in found.get(m, {}).get("scenes", scenes)
    ]


def point_command(point: Point, suite: Suite, data: Path, work: Path) -> list[str]:
    """The training command of a point (what ``execute`` runs, without running it)."""
    run, scene = point.run(suite), suite.scenes[point.scene]
    parser = suite.parser_args(point.scene, suite.equal_time["protocol"])
    extra = point.flags(suite)
    return train_command(run, data / scene["path"], work / point.scene / "runs", parser, extra, threads=THREADS)


def too_short(log: Path) -> str | None:
    """The train CLI's "--time-budget ... is too short" line in a failed run's log, or None (another failure)."""
    found = TOO_SHORT.search(log.read_text(errors="replace")) if log.is_file() else None
    return found.group(0) if found else None


def execute(point: Point, suite: Suite, data: Path, work: Path, lpips: Path, jobs: int) -> dict:
    """Train and evaluate one point; its row (planned and actual training seconds from the run's metrics)."""
    started, run, iterations = time.perf_counter(), point.run(suite), budget_iterations(point.budget)
    size = {"budget_iterations": iterations} if iterations else {"budget_seconds": parse_duration(point.budget)}
    row = {
        "scene": point.scene, "method": point.method, "budget": point.budget, **size, "flags": point.flags(suite),
        "threads": THREADS, "jobs": jobs, "machine": cpu_and_cores(),
    }  # fmt: skip
    parser = suite.parser_args(point.scene, suite.equal_time["protocol"])
    scene_data, scene_work = data / suite.scenes[point.scene]["path"], work / point.scene
    try:
        trained = train_and_eval(
            run, scene_data, parser, scene_work, lpips, point.scene, point.flags(suite), threads=THREADS
        )
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
        "planned_iterations": done.get("planned_iterations", iterations),
        "seconds_per_iteration": seconds / iterations, "psnr": trained["psnr"], "ssim": trained["ssim"],
        "lpips": trained["lpips"], "train_threads": trained["train_threads"],
        "train_view_ids": trained["train_view_ids"], "run_dir": trained["run_dir"],
        "seconds": time.perf_counter() - started,
    }  # fmt: skip
