"""What the scripts in ``benchmarks/`` share: child processes timed, JSONL results, BENCHMARKS.md sections, and the
suite (``suite.toml``) with the setting names it is written in."""

from __future__ import annotations

import argparse
import functools
import json
import os
import platform
import re
import shutil
import subprocess
import sys
import threading
import time
from collections.abc import Callable, Iterable, Iterator, Sequence
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import tomllib

from fourierf_plugin.utils.console import CPU_THREADS_NOTE

BIN = Path(sys.executable).parent
REPO = Path(__file__).resolve().parents[1]
TRAIN, EVAL = (str(BIN / "fourierf-train"),), (str(BIN / "fourierf-eval"),)
LPIPS = "lpips/lpips_alex_v0.1.pth"  # the LPIPS-alex weights, under --shared
LEGO_VIEWS = ("27", "76", "97", "99")
PCPU_LEGO_PARSER = ["blender-data", "--downscale", "4", "--test-every", "8", "--view-ids", *LEGO_VIEWS]  # 100×100
OFFICIAL_OPTIMISER = ["--optimizer.weight-decay", "0", "--optimizer.lr-decay-ratio", "1.0"]  # as the official code
Flags = Sequence[str]  # command-line arguments


def size_flags(rays: int, grid: tuple[int, int]) -> list[str]:
    """Rays per batch and the grid's initial and final side as training flags."""
    return [
        "--pipeline.datamanager.rays-per-batch", str(rays),
        "--pipeline.model.field.n-voxels-init", str(grid[0] ** 3),
        "--pipeline.model.field.n-voxels-final", str(grid[1] ** 3),
    ]  # fmt: skip


GRID_FLAGS = [*size_flags(1024, (64, 128)), "--steps-per-save", "100000"]


def arguments(doc: str | None, work: str | None) -> argparse.ArgumentParser:
    """A script's parser with the options every script has: --shared, --work (under outputs/) and --markdown."""
    ap = argparse.ArgumentParser(description=doc, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--shared", type=Path, default=REPO.parent / "shared")
    ap.add_argument("--work", type=Path, default=None if work is None else REPO / "outputs" / work)
    ap.add_argument("--markdown", type=Path, default=REPO / "BENCHMARKS.md", help="'none' writes no section")
    return ap


def run_timed(cmd: Sequence[str], log: Path, env: dict[str, str] | None = None) -> tuple[float, float, int]:
    """Wall seconds, peak RSS (GB, the child's rusage) and exit code of one child process, its output to ``log``."""
    log.parent.mkdir(parents=True, exist_ok=True)
    start = time.perf_counter()
    with log.open("w") as fh:
        fh.write(" ".join(map(str, cmd)) + "\n\n")
        fh.flush()
        proc = subprocess.Popen(list(map(str, cmd)), stdout=fh, stderr=subprocess.STDOUT, env=env)
        _, status, usage = os.wait4(proc.pid, 0)
    return time.perf_counter() - start, usage.ru_maxrss / 1024**2, os.waitstatus_to_exitcode(status)


def run_checked(cmd: Sequence[str], log: Path, what: str, env: dict[str, str] | None = None) -> tuple[float, float]:
    """``run_timed``, raising when the child failed: its wall seconds and peak RSS (GB)."""
    seconds, rss, code = run_timed(cmd, log, env)
    if code != 0:
        raise RuntimeError(f"{what} failed ({code}); see {log}")
    return seconds, rss


def interleaved(rounds: int, sides: Sequence[str]) -> Iterator[tuple[int, str]]:
    """(round, side) for ``rounds`` rounds of ``sides``, the order rotating so that each side goes first in turn."""
    for i in range(rounds):
        yield from ((i, side) for side in [*sides[i % len(sides) :], *sides[: i % len(sides)]])


def train_cmd(method: str, data: Path, out: Path, stamp: str, *flags: str, program: Sequence[str] = TRAIN) -> list:
    """A ``fourierf-train`` command writing ``out/<scene>/<method>/<stamp>``; later flags win, the parser's last."""
    return [*program, method, "--data", str(data), "--output-dir", str(out), "--timestamp", stamp, *flags]


def eval_report(
    run_dir: Path, work: Path, name: str, *flags: str, env: dict[str, str] | None = None, program: Sequence[str] = EVAL
) -> tuple[dict, float]:
    """``fourierf-eval`` of a run (to ``work/<name>.eval.json``, its log beside): the report and the wall seconds."""
    report = work / f"{name}.eval.json"
    cmd = [*program, "--load-config", str(run_dir / "config.json"), "--output-path", str(report), "--overwrite", *flags]
    seconds, _ = run_checked(cmd, work / f"{name}.eval.log", "evaluation", env)
    return json.loads(report.read_text()), seconds


def run_dir_in(out: Path, method: str, stamp: str) -> Path:
    """The folder ``train_cmd`` wrote under ``out`` (the trainer names the scene folder after the data)."""
    return next(out.glob(f"*/{method}/{stamp}"))


def train_run(
    data: Path, work: Path, name: str, *flags: str, env: dict[str, str] | None = None, program: Sequence[str] = TRAIN
) -> tuple[Path, list[dict], float, float]:
    """A fresh fourierf-vm run in ``work/runs/<name>``: its folder, metrics records, wall seconds and peak RSS (GB)."""
    out = work / "runs" / name
    shutil.rmtree(out, ignore_errors=True)
    cmd = train_cmd("fourierf-vm", data, out, "run", *flags, program=program)
    wall, rss = run_checked(cmd, work / f"{name}.train.log", "training", env)
    run_dir = run_dir_in(out, "fourierf-vm", "run")
    return run_dir, read_jsonl(run_dir / "metrics.jsonl", torn=True), wall, rss


def read_jsonl(path: Path, torn: bool = False) -> list[dict]:
    """The rows of a JSONL file (none if it is missing); ``torn``: skip lines that do not parse (a run's last line)."""
    rows = []
    for line in filter(str.strip, path.read_text().splitlines() if path.exists() else []):
        try:
            rows.append(json.loads(line))
        except json.JSONDecodeError:
            if not torn:
                raise
    return rows


def write_jsonl(path: Path, rows: Iterable[dict], mode: str = "w") -> None:
    with path.open(mode) as fh:
        fh.writelines(json.dumps(row) + "\n" for row in rows)


def log_records(records: list[dict]) -> list[dict]:
    return [r for r in records if "event" not in r and "step" in r]


def done_record(records: list[dict]) -> dict | None:
    """The trainer's closing record (``step``, ``train_seconds``, a --time-budget run's planned seconds)."""
    return next((r for r in reversed(records) if r.get("event") == "done"), None)


def elapsed_by_step(records: list[dict]) -> dict[int, float]:
    return {int(r["step"]): float(r["elapsed_s"]) for r in log_records(records) if "elapsed_s" in r}


def seconds_per_iteration(elapsed: dict[int, float], first: int, last: int) -> float:
    return (elapsed[last] - elapsed[first]) / (last - first)


@dataclass(frozen=True)
class Run:
    method: str
    iters: int
    seed: int
    views: str  # a label for the training-view set
    budget: str | None = None  # "3m" or "800it": sizes the run as a user's, in place of the grid flags
    name: str = ""  # the key's name where it is not the method's (a variant of the method)

    @property
    def key(self) -> str:
        return f"{self.name or self.method}_{self.views}_{self.budget or self.iters}_s{self.seed}"

    def sizes(self) -> list[str]:
        if self.budget is not None and not self.budget.endswith("it"):
            return ["--time-budget", self.budget]
        return ["--max-num-iterations", str(self.iters), *(GRID_FLAGS if self.budget is None else [])]


def train_and_eval(
    run: Run, data: Path, parser_args: Flags, work: Path, lpips: Path, extra: Flags = (), threads: int | None = None
) -> dict:
    """Train one run, evaluate it on the test split: its result row. ``threads`` caps torch's CPU threads in both."""
    out_dir = work / "runs"
    # A run interrupted earlier left its directory without a result; a new run would otherwise go to "<key>-1".
    for earlier in [*out_dir.glob(f"*/{run.method}/{run.key}"), *out_dir.glob(f"*/{run.method}/{run.key}-1")]:
        shutil.rmtree(earlier, ignore_errors=True)
    train_log = work / f"{run.key}.train.log"
    cmd = train_command(run, data, out_dir, parser_args, extra, threads)
    train_s, train_rss = run_checked(cmd, train_log, "training")
    run_dir = run_dir_in(out_dir, run.method, run.key)
    views = json.loads((run_dir / "views.json").read_text())
    row = {
        "key": run.key, "method": run.method, "iters": run.iters, "seed": run.seed, "views": run.views,
        "train_view_ids": views["train_view_ids"], "train_seconds": train_s, "train_peak_rss_gb": train_rss,
        "run_dir": str(run_dir), "machine": cpu_and_cores(), "train_threads": threads_used(train_log),
        "revived_batches": revived_batches(run_dir / "metrics.jsonl"),
    }  # fmt: skip
    return row | evaluate(run_dir, run.key, work, lpips, threads=threads)


def train_command(
    run: Run, data: Path, out: Path, parser_args: Flags, extra: Flags = (), threads: int | None = None
) -> list[str]:
    """The ``fourierf-train`` command of one run: its sizes, then ``extra`` (later flags win), the parser last."""
    flags = ["--seed", str(run.seed), *run.sizes(), *extra, *thread_flags(threads), *parser_args]
    return train_cmd(run.method, data, out, run.key, *flags)


def threads_used(train_log: Path) -> int | None:
    """The CPU thread count the trainer reported in its log (None: not found): only one thread is reproducible."""
    found = CPU_THREADS_NOTE.search(train_log.read_text(errors="replace")) if train_log.is_file() else None
    return int(found.group(1)) if found else None


def revived_batches(metrics: Path) -> int | None:
    """Batches on which the run revived a dead density field, at its last logged step (None: it cannot revive)."""
    counts = [r["revived_batches"] for r in log_records(read_jsonl(metrics, torn=True)) if "revived_batches" in r]
    return int(counts[-1]) if counts else None


def thread_flags(threads: int | None) -> list[str]:
    return [] if threads is None else ["--threads", str(threads)]


def evaluate(
    run_dir: Path, key: str, work: Path, lpips: Path, *flags: str, split: str = "test", threads: int | None = None
) -> dict:
    """A run's metrics and timings on one split (keys prefixed with the split but for test's); ``flags``: the eval's."""
    flags = ("--lpips-weights", str(lpips), "--split", split, *thread_flags(threads), *flags)
    report, eval_s = eval_report(run_dir, work, key if split == "test" else f"{key}.{split}", *flags)
    metrics = {k: report["results"][k] for k in ("psnr", "ssim", "lpips")}
    if split != "test":
        return {f"{split}_{k}": v for k, v in metrics.items()} | {f"{split}_view_ids": report.get("view_ids")}
    return metrics | {
        "test_views": report["num_views"], "eval_seconds": eval_s,
        "eval_render_seconds": report["timings"]["render_seconds_total"],
    }  # fmt: skip


@dataclass(frozen=True)
class Job:
    key: str  # the row's key in the results
    logs: Path  # its logs' path less ``.train.log`` / ``.eval.log``: a failure prints the last one's end
    execute: Callable[[], dict]


def summary(row: dict) -> str:
    if "too_short" in row:
        return f"budget too short: {row['too_short']}"
    if "trained_seconds" in row:
        return f"test {row['psnr']:.2f}  {row['iterations']} iterations in {row['trained_seconds']:.0f}s"
    score = f"val {row['val_psnr']:.2f}" if "val_psnr" in row else f"test {row['psnr']:.2f}"
    return f"{score}  train {row['train_seconds']:.0f}s"


def run_all(jobs: Sequence[Job], path: Path, at_once: int = 1, again: str | None = None) -> None:
    """Run the jobs not yet recorded in ``path`` (all, ``again``), ``at_once`` at a time, recording each as it ends."""
    done = {} if again else load_results(path)
    todo = [job for job in jobs if job.key not in done]
    lock = threading.Lock()

    def one(job: Job) -> None:
        try:
            row = job.execute()
        except RuntimeError as err:  # the log's end says why; the other runs go on
            logs = sorted(job.logs.parent.glob(f"{job.logs.name}*.log"))
            tail = "\n".join(logs[-1].read_text().splitlines()[-15:]) if logs else ""
            print(f"FAILED {job.key}: {err}\n{tail}", flush=True)
            return
        row["key"] = job.key
        with lock:
            record(path, row, again)
        print(f"{job.key}: {summary(row)}", flush=True)

    print(f"{len(todo)} runs to do ({len(jobs) - len(todo)} recorded)", flush=True)
    with ThreadPoolExecutor(max(1, at_once)) as pool:
        list(pool.map(one, todo))


def record(path: Path, row: dict, again: str | None = None) -> None:
    """Append a finished row; run ``--again``, a recorded key's earlier row moves to ``repeats.jsonl`` with the note."""
    held = load_results(path) if again else {}
    if (earlier := held.pop(row["key"], None)) is not None:
        write_jsonl(path.with_name(REPEATS), [earlier | {"repeat": again}], "a")
        write_jsonl(path.with_suffix(".tmp"), held.values())
        path.with_suffix(".tmp").replace(path)  # atomically
    write_jsonl(path, [row], "a")


def load_results(path: Path) -> dict[str, dict]:
    return {r["key"]: r for r in read_jsonl(path)}


def fmt(values: list[float], digits: int) -> str:
    if len(values) == 1:
        return f"{values[0]:.{digits}f}"
    return f"{np.mean(values):.{digits}f} ± {np.std(values):.{digits}f}"


def md_row(cells: Iterable[object]) -> str:
    return "| " + " | ".join(map(str, cells)) + " |"


def table(head: Sequence[str], rows: Iterable[str]) -> list[str]:
    """A markdown table: the header of ``head``, its separator, then ``rows`` (each already a row)."""
    return [md_row(head), "|" + "---|" * len(head), *rows]


def titled_table(intro: str, head: Sequence[str], rows: list[str]) -> list[str]:
    """``table`` after a paragraph; nothing where there are no rows."""
    return [intro, "", *table(head, rows), ""] if rows else []


def markers(name: str, script: str) -> tuple[str, str]:
    """The comments that open and close a generated section of BENCHMARKS.md."""
    return f"<!-- {name}:begin (generated by benchmarks/{script}; do not edit) -->", f"<!-- {name}:end -->"


def write_section(markdown: Path, name: str, script: str, body: list[str]) -> None:
    """Print a script's section and replace (or append) it in ``markdown`` between its markers (not for 'none')."""
    print("\n".join(body))
    if str(markdown).lower() == "none":
        return
    begin, end = markers(name, script)
    section = "\n".join([begin, *body, end])
    header = "# Benchmarks\n\nAll numbers below are written by the scripts in `benchmarks/` (never by hand).\n"
    text = markdown.read_text() if markdown.exists() else header
    if begin in text and end in text:
        head, rest = text.split(begin, 1)
        text = head + section + rest.split(end, 1)[1]
    else:
        text = text.rstrip("\n") + "\n\n" + section + "\n"
    markdown.write_text(text)


def section_head(title: str, command: str, settings: str | None = None, machine: str | None = None) -> list[str]:
    """A BENCHMARKS.md section's opening lines: title, machine (this one unless given) and command, what was run."""
    machine_line = f"Machine: {machine or machine_description()}. Command: `{command}`."
    return [f"## {title}", "", machine_line, *([settings] if settings else []), ""]


def machine_description() -> str:
    import torch

    return f"{cpu_and_cores()}, torch {torch.__version__}, {torch.get_num_threads()} threads"


def cpu_and_cores() -> str:
    cpuinfo = Path("/proc/cpuinfo")
    lines = cpuinfo.read_text().splitlines() if cpuinfo.is_file() else []
    models = [line.split(":", 1)[1].strip() for line in lines if line.startswith("model name")]
    return f"{models[0] if models else platform.processor() or platform.machine()}, {os.cpu_count()} cores"


# The suite: methods × scenes × protocols × settings × seeds, read from suite.toml.

RESULTS = REPO / "benchmarks" / "results"  # each family's committed rows: <family>/results.jsonl
REPEATS = "repeats.jsonl"  # beside the results: earlier rows of keys run again, each with its ``repeat`` note


@dataclass(frozen=True)
class Protocol:
    name: str
    iters: int
    rays: int
    grid: tuple[int, int]  # the grid's initial and final side
    lego_downscale: int
    scenes: Sequence[str] = ("lego", "fern")
    curve_of: str | None = None  # the protocol of the same sizes at 800 iterations whose val choice a curve trains

    def flags(self) -> list[str]:
        return [*size_flags(self.rays, self.grid), "--steps-per-save", "100000"]


@dataclass(frozen=True)
class Suite:
    methods: list[str]
    seeds: list[int]
    protocols: dict[str, Protocol]
    scenes: dict[str, dict]
    settings: dict[str, tuple[str, ...]]
    tokens: dict[str, list[str]]  # a setting's words and the flags they stand for
    valued: dict[str, list[str]]
    curriculum_only: list[str]  # the words tensorf-vm (no masks) skips: its run would repeat another
    targets: list[dict]
    rule_along_the_budget: dict[str, dict[str, str]]
    grids: list[dict]
    curve_every: int
    equal_time: dict

    def parser_args(self, scene: str, protocol: str) -> list[str]:
        args = list(self.scenes[scene]["parser"])
        if args[0] == "blender-data":
            args[1:1] = ["--downscale", str(self.protocols[protocol].lego_downscale)]
        return args


@functools.cache
def load_suite() -> Suite:
    data = tomllib.loads(Path(__file__).with_name("suite.toml").read_text())
    protocols = {name: Protocol(name, **p | {"grid": tuple(p["grid"])}) for name, p in data["protocols"].items()}
    settings = {scene: tuple(names) for scene, names in data["settings"].items()}
    return Suite(**data | {"protocols": protocols, "settings": settings})


def setting_flags(setting: str) -> list[str]:
    """The ``fourierf-train`` flags a setting's name stands for, in the words of suite.toml's [tokens] and [valued]."""
    suite, flags = load_suite(), []
    for token in setting.split("-"):
        match = re.fullmatch(r"([a-z0-9]*?[a-z])(\d+(?:\.\d+)?)", token)
        if token in suite.tokens:
            flags += suite.tokens[token]
        elif match and match[1] in suite.valued:
            n = int(float(match[2]))
            values = {"v": match[2], "v3": 3 * n, "cube": n**3, "half_cube": (n // 2) ** 3}
            flags += [flag.format(**values) for flag in suite.valued[match[1]]]
        else:
            known = f"{', '.join(suite.tokens)}, or one of {', '.join(suite.valued)} and a number"
            raise ValueError(f"{setting}: no such token {token!r}; a token is {known}")
    return flags


def applies(method: str, setting: str) -> bool:
    only = tuple(load_suite().curriculum_only)
    return method != "tensorf-vm" or not any(part.startswith(only) for part in setting.split("-"))


def rows_by(results: dict[str, dict], scene: str, protocol: str, method: str) -> dict[str, list[dict]]:
    """Recorded rows of one (scene, protocol, method) by setting."""
    out: dict[str, list[dict]] = {}
    for r in results.values():
        if (r["scene"], r["protocol"], r["method"]) == (scene, protocol, method):
            out.setdefault(r["setting"], []).append(r)
    return out


def val_by_seed(rows: list[dict], seeds: Sequence[int]) -> dict[int, float]:
    """A setting's val PSNR per seed of ``seeds`` that it ran on, in their order."""
    recorded = {r["seed"]: r["val_psnr"] for r in rows}
    return {seed: recorded[seed] for seed in seeds if seed in recorded}


def chosen_setting(groups: dict[str, list[dict]], seeds: Sequence[int]) -> str | None:
    """The best mean val PSNR over ``seeds`` among settings run on all of them, else the first seed's best: one seed's
    val PSNR moves by more than many settings differ, so the best single-seed setting is mostly the luckiest."""
    seeded = {s: vals for s, rows in groups.items() if len(vals := val_by_seed(rows, seeds)) == len(seeds)}
    if seeded:
        return max(seeded, key=lambda s: float(np.mean(list(seeded[s].values()))))
    first = {s: vals[seeds[0]] for s, rows in groups.items() if (vals := val_by_seed(rows, seeds[:1]))}
    return max(first, key=first.__getitem__) if first else None
