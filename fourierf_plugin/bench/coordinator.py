"""The coordinating side of a bench: its output folder, which runs are still to do, collecting results, the report.

Why separate from the CLI: the benchmark scripts drive the same steps programmatically (and tests do too).
"""

from __future__ import annotations

import json
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path

from fourierf_plugin.bench import report, results
from fourierf_plugin.bench.executors import Executor
from fourierf_plugin.bench.runner import RunResult, RunTask, execute_run
from fourierf_plugin.engine.run_dir import timestamp_now
from fourierf_plugin.utils.errors import fail

REPORT = "report.md"
PLAN = "plan.json"


def claim_output_dir(base: Path) -> Path:
    """A new ``base/<timestamp>[-N]/`` (never an existing folder: a bench never overwrites another)."""
    stamp = timestamp_now()
    try:
        base.mkdir(parents=True, exist_ok=True)
        for suffix in range(1000):
            candidate = base / (stamp if suffix == 0 else f"{stamp}-{suffix}")
            try:
                candidate.mkdir()
                return candidate
            except FileExistsError:
                continue
    except OSError as err:
        fail(f"cannot create the bench folder under {base}: {err}", "choose a writable --output-dir")
    fail(f"too many bench folders named {stamp} under {base}", "choose another --output-dir")


def resume_dir(path: Path) -> Path:
    if not (path / PLAN).is_file():
        fail(
            f"--resume {path} is not a bench folder (it has no {PLAN})", "pass a folder an earlier fourierf-bench made"
        )
    return path


def write_plan(out_dir: Path, tasks: Sequence[RunTask], settings: dict) -> None:
    """Record the runs and settings; a resumed bench given more runs keeps the earlier ones too (one CSV, one plan)."""
    path = out_dir / PLAN
    earlier = json.loads(path.read_text()) if path.is_file() else {"settings": [], "runs": []}
    runs = {r["key"]: r for r in earlier["runs"]}
    runs |= {t.spec.key: t.spec.as_dict() | {"key": t.spec.key} for t in tasks}
    history = earlier["settings"] if isinstance(earlier["settings"], list) else [earlier["settings"]]
    plan = {"settings": [*history, settings], "runs": list(runs.values())}
    path.write_text(json.dumps(plan, indent=2, default=str) + "\n")


def still_to_run(tasks: Sequence[RunTask], out_dir: Path) -> list[RunTask]:
    """The tasks whose run has no finished record yet (``--resume`` skips the others)."""
    done = results.read_runs(out_dir / results.RUNS)
    return [t for t in tasks if t.spec.key not in done]


@dataclass
class Outcome:
    out_dir: Path
    finished: list[str] = field(default_factory=list)
    failed: dict[str, str] = field(default_factory=dict)
    markdown: list[str] = field(default_factory=list)
    plots: list[Path] = field(default_factory=list)


def record_result(out_dir: Path, result: RunResult) -> None:
    """Append a finished run's rows and record (rows first: a run counts as done only once both are written)."""
    results.append_rows(out_dir / results.MEASUREMENTS, result.rows)
    results.append_run(out_dir / results.RUNS, result.record)


def run_tasks(
    tasks: Sequence[RunTask],
    executor: Executor,
    out_dir: Path,
    on_result: Callable[[RunResult, int, int], None] | None = None,
    run: Callable[[RunTask], RunResult] = execute_run,
) -> Outcome:
    outcome = Outcome(out_dir)
    for i, result in enumerate(executor.map(run, tasks), start=1):
        if result.ok:
            record_result(out_dir, result)
            outcome.finished.append(result.key)
        else:
            outcome.failed[result.key] = result.error or "failed"
        if on_result is not None:
            on_result(result, i, len(tasks))
    return outcome


def build_report(
    out_dir: Path, title: str, preamble: Sequence[str] = (), image_dir: str | None = None
) -> tuple[list[str], list[Path]]:
    """Plots and ``report.md`` in ``out_dir`` from its results files; returns the markdown body and plot paths.

    ``image_dir`` is how the markdown refers to the plots' folder (report.md sits beside them; BENCHMARKS.md may not).
    """
    rows = results.read_rows(out_dir / results.MEASUREMENTS)
    records = results.read_runs(out_dir / results.RUNS)
    plots, note = report.make_plots(rows, records, out_dir)
    body = report.markdown(rows, records, title=title, preamble=preamble, plots=[str(p) for p in plots],
                           plots_note=note, image_dir=image_dir)  # fmt: skip
    local = report.markdown(rows, records, title=title, preamble=preamble, plots=[str(p) for p in plots],
                            plots_note=note)  # fmt: skip
    (out_dir / REPORT).write_text("\n".join(local) + "\n")
    return body, plots
