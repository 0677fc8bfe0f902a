"""Reading a run's metrics.jsonl: training seconds at each logged step and the per-phase time breakdown.

The trainer's ``--profile-phases`` adds ``"phases": {name: seconds since the previous log record}`` to each log record
and ``"phases_total"`` to the final ``{"event": "done"}`` record. Runs without it simply have no phases; everything
here returns None or empty results then, so a report never depends on the profiler being present.
"""

from __future__ import annotations

import json
from pathlib import Path

from fourierf_plugin.bench.sweep import FINAL_TAIL
from fourierf_plugin.utils import phases as profiler

FOURIER_PHASES = ("fourier_filter", "fourier_filter_backward")


def read_metrics(path: Path) -> list[dict]:
    """Records of a metrics.jsonl (a missing file or a torn last line gives what could be read)."""
    if not Path(path).is_file():
        return []
    records = []
    for line in Path(path).read_text().splitlines():
        try:
            records.append(json.loads(line))
        except json.JSONDecodeError:
            continue
    return records


def log_records(records: list[dict]) -> list[dict]:
    return [r for r in records if "event" not in r and "step" in r]


def done_record(records: list[dict]) -> dict | None:
    return next((r for r in reversed(records) if r.get("event") == "done"), None)


def elapsed_by_step(records: list[dict]) -> dict[int, float]:
    """Training seconds since the start of the run at every logged step."""
    return {int(r["step"]): float(r["elapsed_s"]) for r in log_records(records) if "elapsed_s" in r}


def phases_total(records: list[dict]) -> dict[str, float] | None:
    done = done_record(records)
    total = done.get("phases_total") if done else None
    return {k: float(v) for k, v in total.items()} if total else None


def phases_final(records: list[dict], iters: int, tail: float = FINAL_TAIL) -> dict[str, float] | None:
    """Phase seconds summed over the log intervals that lie wholly in the last ``tail`` of the steps."""
    summed, _ = phases_after(records, (1.0 - tail) * iters)
    return summed or None


def phases_after(records: list[dict], start: float) -> tuple[dict[str, float], int]:
    """Phase seconds summed over the log intervals that begin at or after step ``start``, and how many steps
    those intervals cover."""
    summed: dict[str, float] = {}
    previous_step, steps = 0, 0
    for record in log_records(records):
        step = int(record["step"])
        if previous_step >= start and isinstance(record.get("phases"), dict):
            for name, seconds in record["phases"].items():
                summed[name] = summed.get(name, 0.0) + float(seconds)
            steps += step - previous_step
        previous_step = step
    return summed, steps


def shares(phases: dict[str, float]) -> dict[str, float]:
    """Each phase's share of iteration time (the profiler's phases are exclusive, so they sum to it), largest first."""
    return dict(sorted(profiler.shares(phases).items(), key=lambda kv: -kv[1]))


def fourier_share(phases: dict[str, float] | None) -> float | None:
    """(fourier_filter + fourier_filter_backward) / total; None without a breakdown or without any filtering phase."""
    if not phases or not any(name in phases for name in FOURIER_PHASES):
        return None
    return sum(profiler.shares(phases).get(name, 0.0) for name in FOURIER_PHASES)
