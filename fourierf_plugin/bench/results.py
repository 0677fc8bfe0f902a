"""The bench's result files: ``measurements.csv`` (one row per evaluated checkpoint) and ``runs.jsonl`` (one record
per finished run: timings, memory, phase breakdown), both appended by the coordinating process only.

Why the coordinator writes: whatever executor ran a run (a local pool, a Ray cluster), its result comes back by
value, so the files look the same, and a run appears in them only once it is completely evaluated (resume skips it).
"""

from __future__ import annotations

import csv
import json
import math
from pathlib import Path

COLUMNS = (
    "key", "method", "iters", "downscale", "grid_voxels", "grid_side", "init_voxels", "step_ratio", "batch_size",
    "f0", "ramp_fraction", "delta_per_iter", "seed", "eval_points", "profiled",
    "step", "fraction", "train_seconds_at_step", "train_seconds_total", "wall_seconds", "peak_rss_gb",
    "psnr", "ssim", "lpips", "test_views", "eval_seconds", "run_dir",
)  # fmt: skip
_INTS = {"iters", "downscale", "grid_voxels", "init_voxels", "batch_size", "seed", "eval_points", "step", "test_views"}
_FLOATS = {
    "grid_side", "step_ratio", "f0", "ramp_fraction", "delta_per_iter", "fraction", "train_seconds_at_step",
    "train_seconds_total", "wall_seconds", "peak_rss_gb", "psnr", "ssim", "lpips", "eval_seconds",
}  # fmt: skip
MEASUREMENTS = "measurements.csv"
RUNS = "runs.jsonl"


def _cell(value: object) -> str:
    if value is None:
        return ""
    if isinstance(value, float):
        return "inf" if math.isinf(value) else repr(value)
    return str(value)


def _parse(name: str, text: str) -> object:
    if text == "":
        return None
    if name in _INTS:
        return int(text)
    if name in _FLOATS:
        return float(text)
    if name == "profiled":
        return text == "True"
    return text


def append_rows(path: Path, rows: list[dict]) -> None:
    """Append rows under the fixed header (keys outside ``COLUMNS`` are not written)."""
    new = not Path(path).exists()
    with Path(path).open("a", newline="") as fh:
        writer = csv.DictWriter(fh, fieldnames=COLUMNS)
        if new:
            writer.writeheader()
        for row in rows:
            writer.writerow({k: _cell(row.get(k)) for k in COLUMNS})


def read_rows(path: Path) -> list[dict]:
    """Typed rows of a measurements CSV; [] when it does not exist yet."""
    if not Path(path).is_file():
        return []
    with Path(path).open(newline="") as fh:
        return [{k: _parse(k, v or "") for k, v in row.items() if k in COLUMNS} for row in csv.DictReader(fh)]


def append_run(path: Path, record: dict) -> None:
    with Path(path).open("a") as fh:
        fh.write(json.dumps(record) + "\n")


def read_runs(path: Path) -> dict[str, dict]:
    """Finished runs by key (the last record of a key wins)."""
    if not Path(path).is_file():
        return {}
    runs = {}
    for line in Path(path).read_text().splitlines():
        try:
            record = json.loads(line)
        except json.JSONDecodeError:
            continue
        runs[record["key"]] = record
    return runs
