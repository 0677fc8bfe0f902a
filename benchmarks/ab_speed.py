"""Interleaved A/B of two versions of fourierf on protocol P-CPU: is the new one as fast as the old one?

Each version is exported into its own flat folder (the package with ``method_configs`` and ``data/parsers`` put in
their installed places) and run from there with ``python -m fourierf_plugin.scripts.train`` / ``.eval``, so both
sides run in this one invocation on this machine, alternating which goes first in each pair:

    python benchmarks/ab_speed.py --old HEAD            # the working tree against the last commit, 3 pairs
    python benchmarks/ab_speed.py --old abc123 --new def456 --pairs 5

P-CPU: lego 4 views (r_27 r_76 r_97 r_99), 100×100, batch 1024, grid 64³ → 128³, 800 iterations, the official code's
optimiser (weight decay 0, no lr decay), 25 test views. Reported per side: the median final-phase seconds per
iteration (iterations 601–800, from the runs' own logs, no profiler) and the median time to render the 25 test views
(``fourierf-eval``'s render seconds), the new/old ratios, and the test PSNR of each run (equal seeds must give equal
PSNRs when the arithmetic did not change). Takes about 4 minutes per run on two cores; keep the machine quiet.
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import statistics
import subprocess
import sys
from pathlib import Path

from fourierf_plugin.bench.phases import elapsed_by_step, read_metrics
from fourierf_plugin.bench.protocol import GRID_FLAGS, run_timed

REPO = Path(__file__).resolve().parents[1]
SOURCES = ("fourierf_plugin", "method_configs", "data/parsers")
INSTALLED = {"method_configs": "fourierf_plugin/method_configs", "data/parsers": "fourierf_plugin/data/parsers"}
VIEWS = ("27", "76", "97", "99")
OPTIMISER = ["--optimizer.weight-decay", "0", "--optimizer.lr-decay-ratio", "1.0"]
FINAL = (600, 800)  # the final phase: after the last upsample (step 560)
ITERATION_TIMER = """
import sys, time, torch
from fourierf_plugin.configs.base import load_config
from fourierf_plugin.engine.checkpoint import load_latest_checkpoint
from fourierf_plugin.engine.optimizers import build_optimizer
from fourierf_plugin.engine.trainer import TrainerConfig
try:  # this project after its redesign
    from fourierf_plugin.accel.allocator import keep_freed_memory
    from fourierf_plugin.engine.machine import seed_everything
    from fourierf_plugin.method_configs import config_registry
    registry = (config_registry(),)
except ImportError:  # before it
    from fourierf_plugin.engine.trainer import seed_everything
    from fourierf_plugin.utils.allocator import keep_freed_memory
    registry = ()
keep_freed_memory()
run_dir, step, warmup, iters = sys.argv[1], int(sys.argv[2]), int(sys.argv[3]), int(sys.argv[4])
config = load_config(run_dir + "/config.json", TrainerConfig, *registry)
pipeline = config.pipeline.setup(device=torch.device("cpu"), max_iters=800, generator=seed_everything(config.seed))
pipeline.load_state_dict(load_latest_checkpoint(run_dir + "/checkpoints")[1]["pipeline"])
optimizer = build_optimizer(config.optimizer, pipeline.model.param_groups())
for i in range(warmup + iters):
    if i == warmup:
        start = time.perf_counter()
    loss, _ = pipeline.train_step(step)
    optimizer.zero_grad(set_to_none=True)
    loss.backward()
    optimizer.step()
print((time.perf_counter() - start) / iters)
"""


def export_tree(rev: str | None, where: Path) -> Path:
    """The package of ``rev`` (None: the working tree, as it is now) laid out as installed, under ``where``."""
    if where.exists():
        shutil.rmtree(where)
    where.mkdir(parents=True)
    if rev is None:
        listed = subprocess.run(
            ["git", "ls-files", "--cached", "--others", "--exclude-standard", *SOURCES],
            cwd=REPO, check=True, capture_output=True, text=True,
        ).stdout.split()  # fmt: skip
        for name in listed:
            if (REPO / name).is_file():
                (where / name).parent.mkdir(parents=True, exist_ok=True)
                shutil.copy2(REPO / name, where / name)
    else:
        archive = subprocess.run(["git", "archive", rev, *SOURCES], cwd=REPO, check=True, capture_output=True).stdout
        subprocess.run(["tar", "-x", "-C", str(where)], input=archive, check=True)
    for source, target in INSTALLED.items():
        shutil.move(str(where / source), str(where / target))
    return where


def run_side(code: Path, label: str, seed: int, work: Path, shared: Path) -> dict:
    """Train and evaluate one P-CPU run with the package in ``code``; its timings and PSNR."""
    env = dict(os.environ, PYTHONPATH=str(code))
    out = work / "runs" / label
    shutil.rmtree(out, ignore_errors=True)
    train = [
        sys.executable, "-P", "-m", "fourierf_plugin.scripts.train", "fourierf-vm",
        "--data", str(shared / "data/blender/lego"), "--output-dir", str(out), "--timestamp", "run",
        "--seed", str(seed), "--max-num-iterations", "800",
        "--log-every", "50", *GRID_FLAGS, *OPTIMISER,
        "blender-data", "--downscale", "4", "--test-every", "8", "--view-ids", *VIEWS,
    ]  # fmt: skip
    wall, _, code_ = run_timed(train, work / f"{label}.train.log", env)
    if code_ != 0:
        raise RuntimeError(f"training failed; see {work / f'{label}.train.log'}")
    run_dir = out / "lego" / "fourierf-vm" / "run"
    elapsed = elapsed_by_step(read_metrics(run_dir / "metrics.jsonl"))
    report = work / f"{label}.eval.json"
    evaluate = [
        sys.executable, "-P", "-m", "fourierf_plugin.scripts.eval", "--load-config", str(run_dir / "config.json"),
        "--output-path", str(report), "--render-dir", "none",
        "--lpips-weights", str(shared / "lpips/lpips_alex_v0.1.pth"),
    ]  # fmt: skip
    _, _, code_ = run_timed(evaluate, work / f"{label}.eval.log", env)
    if code_ != 0:
        raise RuntimeError(f"evaluation failed; see {work / f'{label}.eval.log'}")
    result = json.loads(report.read_text())
    return {
        "label": label,
        "seed": seed,
        "train_wall_s": wall,
        "final_s_per_it": (elapsed[FINAL[1]] - elapsed[FINAL[0]]) / (FINAL[1] - FINAL[0]),
        "render_s": result["timings"]["render_seconds_total"],
        "psnr": result["results"]["psnr"],
    }


def time_iterations(code: Path, run_dir: Path, step: int = 700, warmup: int = 5, iters: int = 40) -> float:
    """Seconds per training iteration at ``step`` on a run's final saved state, in a fresh process of ``code``."""
    env = dict(os.environ, PYTHONPATH=str(code))
    cmd = [sys.executable, "-P", "-c", ITERATION_TIMER, str(run_dir), str(step), str(warmup), str(iters)]
    out = subprocess.run(cmd, env=env, check=True, capture_output=True, text=True).stdout
    return float(out.split()[-1])


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--old", default="HEAD", help="git revision of the baseline")
    ap.add_argument("--new", default=None, help="git revision to compare (default: the working tree)")
    ap.add_argument("--pairs", type=int, default=3)
    ap.add_argument("--seeds", type=int, nargs="+", default=[20211202, 1, 2])
    ap.add_argument("--shared", type=Path, default=REPO.parent / "shared")
    ap.add_argument("--work", type=Path, default=REPO / "outputs" / "bench_ab_speed")
    ap.add_argument("--iteration-repeats", type=int, default=6, help="alternating in-process timings per side")
    args = ap.parse_args()
    args.work.mkdir(parents=True, exist_ok=True)
    codes = {"old": export_tree(args.old, args.work / "code-old"), "new": export_tree(args.new, args.work / "code-new")}
    rows = []
    for i in range(args.pairs):
        seed = args.seeds[i % len(args.seeds)]
        order = ("old", "new") if i % 2 == 0 else ("new", "old")
        for side in order:
            row = run_side(codes[side], f"{side}-{i}", seed, args.work, args.shared) | {"side": side}
            rows.append(row)
            print(json.dumps(row), flush=True)
    (args.work / "results.jsonl").write_text("".join(json.dumps(r) + "\n" for r in rows))
    med = {
        side: {k: statistics.median(r[k] for r in rows if r["side"] == side) for k in ("final_s_per_it", "render_s")}
        for side in ("old", "new")
    }
    print(f"\nold = {args.old}, new = {args.new or 'working tree'}; {args.pairs} interleaved pairs (medians)")
    print("| | old | new | new / old |\n|---|---|---|---|")
    for key, name in (("final_s_per_it", "final-phase s/iteration"), ("render_s", "render 25 test views s")):
        print(f"| {name} | {med['old'][key]:.3f} | {med['new'][key]:.3f} | {med['new'][key] / med['old'][key]:.3f} |")
    # The final phase again, with less noise: 40 iterations at step 700 on each side's own final state (the same
    # state: equal seeds train identically), in short processes alternating old, new, old, ...
    first = {side: args.work / "runs" / f"{side}-0" / "lego" / "fourierf-vm" / "run" for side in ("old", "new")}
    timings: dict[str, list[float]] = {"old": [], "new": []}
    for i in range(args.iteration_repeats):
        for side in ("old", "new") if i % 2 == 0 else ("new", "old"):
            timings[side].append(time_iterations(codes[side], first[side]))
    (args.work / "iterations.json").write_text(json.dumps(timings))
    old_it, new_it = statistics.median(timings["old"]), statistics.median(timings["new"])
    print(
        f"| s/iteration at step 700, in-process ({args.iteration_repeats} alternating repeats of 40) | "
        f"{old_it:.4f} | {new_it:.4f} | {new_it / old_it:.3f} |"
    )
    for side in ("old", "new"):
        psnrs = [f"{r['psnr']:.4f} (seed {r['seed']})" for r in rows if r["side"] == side]
        print(f"test PSNR {side}: " + ", ".join(psnrs))


if __name__ == "__main__":
    main()
