"""Shared pieces of the scripts in ``benchmarks/``: timed child processes, the results file, BENCHMARKS.md sections.

Each run is its own process (`fourierf-train`, then `fourierf-eval`), timed by wall clock with its peak RSS read
from the child's rusage. Results are appended to a JSONL file (finished runs are skipped on a re-run; delete a line
to re-time it) and a section of BENCHMARKS.md between markers is regenerated from them.
"""

from __future__ import annotations

import json
import os
import platform
import shutil
import sys
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from fourierf_plugin.bench.phases import log_records, read_metrics
from fourierf_plugin.bench.runner import run_timed
from fourierf_plugin.utils.console import CPU_THREADS_NOTE

BIN = Path(sys.executable).parent
GRID_FLAGS = [
    "--pipeline.datamanager.rays-per-batch", "1024",
    "--pipeline.model.field.n-voxels-init", str(64**3),
    "--pipeline.model.field.n-voxels-final", str(128**3),
    "--steps-per-save", "100000",
]  # fmt: skip


@dataclass(frozen=True)
class Run:
    method: str
    iters: int
    seed: int
    views: str  # a label for the training-view set

    @property
    def key(self) -> str:
        return f"{self.method}_{self.views}_{self.iters}_s{self.seed}"


def train_and_eval(
    run: Run,
    data: Path,
    parser_args: Sequence[str],
    work: Path,
    lpips: Path,
    scene: str,
    extra: Sequence[str] = (),
    threads: int | None = None,
) -> dict:
    """Train one run, evaluate it on the test split, and return its result row. ``threads`` caps torch's CPU threads
    in both steps, so that jobs run side by side do not oversubscribe the cores during evaluation either."""
    out_dir = work / "runs"
    run_dir = out_dir / scene / run.method / run.key
    # The harness owns its work folder: a run interrupted earlier left this directory without a result, and a new
    # run would otherwise go to "<key>-1" (runs never overwrite each other).
    shutil.rmtree(run_dir, ignore_errors=True)
    shutil.rmtree(run_dir.with_name(run.key + "-1"), ignore_errors=True)
    train_cmd = [
        str(BIN / "fourierf-train"), run.method, "--data", str(data), "--output-dir", str(out_dir),
        "--timestamp", run.key, "--seed", str(run.seed), "--max-num-iterations", str(run.iters),
        *GRID_FLAGS, *extra, *thread_flags(threads), *parser_args,
    ]  # fmt: skip
    train_log = work / f"{run.key}.train.log"
    train_s, train_rss, code = run_timed(train_cmd, train_log)
    if code != 0:
        raise RuntimeError(f"training failed ({code}); see {train_log}")
    views = json.loads((run_dir / "views.json").read_text())
    row = {
        "key": run.key, "method": run.method, "iters": run.iters, "seed": run.seed, "views": run.views,
        "train_view_ids": views["train_view_ids"], "train_seconds": train_s, "train_peak_rss_gb": train_rss,
        "run_dir": str(run_dir), "machine": cpu_and_cores(), "train_threads": threads_used(train_log),
        "revived_batches": revived_batches(run_dir / "metrics.jsonl"),
    }  # fmt: skip
    return row | evaluate(run_dir, run.key, work, lpips, threads=threads)


def threads_used(train_log: Path) -> int | None:
    """The CPU thread count the trainer reported in its log (None: not found). One thread is reproducible, more are
    not: parallel kernels sum floats in a varying order, which training amplifies, so a rerun must know it."""
    try:
        found = CPU_THREADS_NOTE.search(train_log.read_text(errors="replace"))
    except OSError:
        return None
    return int(found.group(1)) if found else None


def revived_batches(metrics: Path) -> int | None:
    """Batches on which the run revived a dead density field, from its last logged step (None: its field cannot
    revive, or the log predates the count). Where it is 0 the run is TensoRF's ReLU to the bit, so two settings that
    differ only in when they revive trained the same run."""
    counts = [r["revived_batches"] for r in log_records(read_metrics(metrics)) if "revived_batches" in r]
    return int(counts[-1]) if counts else None


def thread_flags(threads: int | None) -> list[str]:
    """``--threads N`` for the train and eval scripts, or nothing (torch's default: every core it sees)."""
    return [] if threads is None else ["--threads", str(threads)]


def evaluate(
    run_dir: Path,
    key: str,
    work: Path,
    lpips: Path,
    split: str = "test",
    checkpoint: Path | None = None,
    threads: int | None = None,
) -> dict:
    """Evaluate a trained run on one split, at its latest checkpoint or ``checkpoint``: metrics and timings for its
    result row (val keys prefixed ``val_``)."""
    tag = "" if split == "test" else f".{split}"
    eval_json = work / f"{key}{tag}.eval.json"
    eval_cmd = [
        str(BIN / "fourierf-eval"), "--load-config", str(run_dir / "config.json"), "--output-path", str(eval_json),
        "--lpips-weights", str(lpips), "--split", split, "--overwrite",
        *(["--checkpoint", str(checkpoint)] if checkpoint is not None else []), *thread_flags(threads),
    ]  # fmt: skip
    eval_s, _, code = run_timed(eval_cmd, work / f"{key}{tag}.eval.log")
    if code != 0:
        raise RuntimeError(f"evaluation failed ({code}); see {work / f'{key}{tag}.eval.log'}")
    report = json.loads(eval_json.read_text())
    metrics = {
        "psnr": report["results"]["psnr"], "ssim": report["results"]["ssim"], "lpips": report["results"]["lpips"],
    }  # fmt: skip
    if split != "test":
        return {f"{split}_{k}": v for k, v in metrics.items()} | {f"{split}_view_ids": report.get("view_ids")}
    return metrics | {
        "test_views": report["num_views"], "eval_seconds": eval_s,
        "eval_render_seconds": report["timings"]["render_seconds_total"],
    }  # fmt: skip


def save_results(path: Path, results: dict[str, dict]) -> None:
    """Rewrite the results file atomically (after rows were updated in place)."""
    tmp = path.with_suffix(".tmp")
    tmp.write_text("".join(json.dumps(row) + "\n" for row in results.values()))
    tmp.replace(path)


def run_plan(plan: Sequence[Run], results_path: Path, execute: Callable[[Run], dict]) -> dict[str, dict]:
    """Execute the runs not yet in the results file; returns the planned rows."""
    results = load_results(results_path)
    for run in plan:
        if run.key in results:
            continue
        print(f"running {run.key} ...", flush=True)
        row = execute(run)
        results[run.key] = row
        with results_path.open("a") as fh:
            fh.write(json.dumps(row) + "\n")
        summary = f"psnr {row['psnr']:.2f}  ssim {row['ssim']:.3f}  lpips {row['lpips']:.3f}"
        print(f"  {summary}  train {row['train_seconds']:.0f}s", flush=True)
    planned = {r.key for r in plan}
    return {k: v for k, v in results.items() if k in planned}


def load_results(path: Path) -> dict[str, dict]:
    if not path.exists():
        return {}
    return {r["key"]: r for r in map(json.loads, path.read_text().splitlines()) if r}


def fmt(values: list[float], digits: int) -> str:
    if len(values) == 1:
        return f"{values[0]:.{digits}f}"
    return f"{np.mean(values):.{digits}f} ± {np.std(values):.{digits}f}"


def results_table(results: dict[str, dict], first_views: str) -> list[str]:
    """Markdown rows grouped by (views, iterations, method), then the FourieRF − TensoRF gaps."""
    groups: dict[tuple, list[dict]] = {}
    for r in results.values():
        groups.setdefault((r["views"], r["iters"], r["method"]), []).append(r)
    lines = [
        "| views | iterations | method | seeds | PSNR ↑ | SSIM ↑ | LPIPS ↓ | train s | peak RSS GB |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    for (views, iters, method), rows in sorted(groups.items(), key=lambda kv: (kv[0][0] != first_views, kv[0][1:])):
        lines.append(
            f"| {views} {rows[0]['train_view_ids']} | {iters} | {method} | {len(rows)} | "
            f"{fmt([r['psnr'] for r in rows], 2)} | {fmt([r['ssim'] for r in rows], 3)} | "
            f"{fmt([r['lpips'] for r in rows], 3)} | {fmt([r['train_seconds'] for r in rows], 0)} | "
            f"{max(r['train_peak_rss_gb'] for r in rows):.2f} |"
        )
    lines += ["", "Gaps (mean PSNR) and training-time ratios:"]
    for views, iters in sorted({(v, i) for v, i, _ in groups}):
        f, t = groups.get((views, iters, "fourierf-vm")), groups.get((views, iters, "tensorf-vm"))
        if f and t:
            gap = np.mean([r["psnr"] for r in f]) - np.mean([r["psnr"] for r in t])
            ratio = np.mean([r["train_seconds"] for r in f]) / np.mean([r["train_seconds"] for r in t])
            lines.append(f"- {views} views, {iters} iterations: fourierf-vm − tensorf-vm = {gap:+.2f} dB; {ratio:.2f}×")
    return lines


def update_benchmarks_md(path: Path, begin: str, end: str, body: list[str]) -> str:
    """Replace (or append) the section between the markers; returns the section."""
    section = "\n".join([begin, *body, end])
    header = "# Benchmarks\n\nAll numbers below are written by the scripts in `benchmarks/` (never by hand).\n"
    text = path.read_text() if path.exists() else header
    if begin in text and end in text:
        head, rest = text.split(begin, 1)
        text = head + section + rest.split(end, 1)[1]
    else:
        text = text.rstrip("\n") + "\n\n" + section + "\n"
    path.write_text(text)
    return section


def section_head(title: str, command: str, settings: str | None = None, machine: str | None = None) -> list[str]:
    """The opening lines every BENCHMARKS.md section shares: title, machine and command, what was run. ``machine``
    replaces this machine's description where the rows were recorded elsewhere (on several machines)."""
    return [
        f"## {title}",
        "",
        f"Machine: {machine or machine_description()}. Command: `{command}`.",
        *([settings] if settings else []),
        "",
    ]


def machine_description() -> str:
    import torch

    return f"{cpu_and_cores()}, torch {torch.__version__}, {torch.get_num_threads()} threads"


def cpu_and_cores() -> str:
    """This machine's CPU model and core count: what a result row records of where it ran."""
    cpu = platform.processor() or platform.machine()
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                cpu = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    return f"{cpu}, {os.cpu_count()} cores"
