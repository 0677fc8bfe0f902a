"""Reading a run's metrics.jsonl: training seconds at each logged step and the per-phase time breakdown.

The trainer's ``--profile-phases`` adds ``"phases": {name: seconds since the previous log record}`` to each log record
and ``"phases_total"`` to the final ``{"event": "done"}`` record. Runs without it simply have no phases; everything
here returns None or empty results then, so a report never depends on the profiler being present.
"""

from __future__ import annotations

import json
from pathlib import Path

from fourierf_plugin.bench.sweep import FINAL_TAIL

FOURIER_PHASES = ("fourier_filter", "fourier_filter_backward")
TOTAL_NAMES = ("total", "iteration")
"""A phase with one of these names is the denominator itself, not a part of it."""


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
    start = (1.0 - tail) * iters
    summed: dict[str, float] = {}
    previous_step = 0
    for record in log_records(records):
        step = int(record["step"])
        if previous_step >= start and isinstance(record.get("phases"), dict):
            for name, seconds in record["phases"].items():
                summed[name] = summed.get(name, 0.0) + float(seconds)
        previous_step = step
    return summed or None


def denominator(phases: dict[str, float]) -> float:
    """The time the phases are shares of: an explicit total when the profiler gives one, else their sum."""
    for name in TOTAL_NAMES:
        if name in phases:
            return float(phases[name])
    return float(sum(phases.values()))


def shares(phases: dict[str, float]) -> dict[str, float]:
    """Each phase's share of iteration time (the total itself is left out), largest first."""
    total = denominator(phases)
    parts = {k: v for k, v in phases.items() if k not in TOTAL_NAMES}
    if total <= 0:
        return dict.fromkeys(parts, 0.0)
    return dict(sorted(((k, v / total) for k, v in parts.items()), key=lambda kv: -kv[1]))


def fourier_share(phases: dict[str, float] | None) -> float | None:
    """(fourier_filter + fourier_filter_backward) / total; None without a breakdown or without any filtering phase."""
    if not phases or not any(name in phases for name in FOURIER_PHASES):
        return None
    total = denominator(phases)
    return sum(phases.get(name, 0.0) for name in FOURIER_PHASES) / total if total > 0 else None
