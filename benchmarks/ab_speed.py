"""Interleaved A/B of two versions of fourierf (each from its own export) on protocol P-CPU: is the new one as fast as
the old one? ``--old-flags`` / ``--new-flags`` time an option instead, in a section of its own.

    python benchmarks/ab_speed.py --old HEAD [--new REV] [--pairs 3] [--scene fern] --describe "what differs"
    python benchmarks/ab_speed.py --old HEAD --new HEAD --new-flags "--pipeline.model.entropy-weight 0.00003"
"""

from __future__ import annotations

import json
import os
import shlex
import shutil
import statistics
import subprocess
import sys
from collections.abc import Sequence
from pathlib import Path

import harness

SOURCES = ("fourierf_plugin", "method_configs", "data/parsers")
INSTALLED = {"method_configs": "fourierf_plugin/method_configs", "data/parsers": "fourierf_plugin/data/parsers"}
MODULE = (sys.executable, "-P", "-m")
SIDES = ("old", "new")
SCENES = {  # per scene: its data under <shared>/data, flags beyond P-CPU's sizes, parser flags, section title, marker
    "lego": {"data": "blender/lego", "flags": harness.OFFICIAL_OPTIMISER, "parser": harness.PCPU_LEGO_PARSER,
             "title": "Speed A/B of a change to a default (lego, interleaved)", "marker": "ab_speed"},
    "fern": {"data": "llff/fern", "flags": [], "parser": ["llff-data", "--num-views", "3"],
             "title": "Speed A/B of a change to a forward-facing default (fern, interleaved)",
             "marker": "ab_speed_fern"},
}  # fmt: skip
FINAL = (600, 800)  # the final phase: after the last upsample (step 560)
ITERATION_TIMER = """
import sys, time, torch
from fourierf_plugin.accel.allocator import keep_freed_memory
from fourierf_plugin.configs.base import load_config
from fourierf_plugin.engine.checkpoint import load_latest_checkpoint
from fourierf_plugin.engine.machine import seed_everything
from fourierf_plugin.engine.optimizers import build_optimizer
from fourierf_plugin.engine.trainer import TrainerConfig
from fourierf_plugin.method_configs import config_registry
keep_freed_memory()
run_dir, step, warmup, iters = sys.argv[1], int(sys.argv[2]), int(sys.argv[3]), int(sys.argv[4])
config = load_config(run_dir + "/config.json", TrainerConfig, config_registry())
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


def section_of(scene: str, option: bool) -> tuple[str, str]:
    """A scene's section title and marker; an option's A/B has a section of its own (its cost, not a new default)."""
    if option:
        return f"Cost of an option on P-CPU {scene} (interleaved A/B of flags)", f"{SCENES[scene]['marker']}_option"
    return SCENES[scene]["title"], SCENES[scene]["marker"]


def git(*args: str) -> str:
    return subprocess.run(["git", *args], cwd=harness.REPO, check=True, capture_output=True, text=True).stdout.strip()


def export_tree(rev: str | None, where: Path) -> Path:
    """The package of ``rev`` (None: the working tree, as it is now) laid out as installed, under ``where``."""
    shutil.rmtree(where, ignore_errors=True)
    where.mkdir(parents=True)
    if rev is None:
        for name in git("ls-files", "--cached", "--others", "--exclude-standard", *SOURCES).split():
            if (harness.REPO / name).is_file():
                (where / name).parent.mkdir(parents=True, exist_ok=True)
                shutil.copy2(harness.REPO / name, where / name)
    else:
        archive = subprocess.run(["git", "archive", rev, *SOURCES], cwd=harness.REPO, check=True, capture_output=True)
        subprocess.run(["tar", "-x", "-C", str(where)], input=archive.stdout, check=True)
    for source, target in INSTALLED.items():
        shutil.move(str(where / source), str(where / target))
    return where


def revision_label(rev: str | None) -> str:
    """What a side ran, for meta.json: ``rev`` with its short commit id, or the working tree on its commit."""
    head = git("rev-parse", "--short", rev or "HEAD")
    if rev is not None:
        return rev if rev.startswith(head) else f"{rev} ({head})"
    dirty = git("status", "--porcelain", "--untracked-files=no", *SOURCES)
    return f"the working tree on {head}" + (", with uncommitted changes" if dirty else "")


def run_side(code: Path, label: str, seed: int, work: Path, shared: Path, scene: str, flags: Sequence[str]) -> dict:
    """One P-CPU run of ``scene`` with the package in ``code`` and the side's ``flags``: its timings and PSNR."""
    env, data = dict(os.environ, PYTHONPATH=str(code)), SCENES[scene]
    sizes = ["--seed", str(seed), "--max-num-iterations", "800", "--log-every", "50", *harness.GRID_FLAGS]
    run_dir, records, wall, _ = harness.train_run(shared / "data" / data["data"], work, label, *sizes, *data["flags"],
                                                  *flags, *data["parser"], env=env,
                                                  program=(*MODULE, "fourierf_plugin.scripts.train"))  # fmt: skip
    lpips = str(shared / harness.LPIPS)
    result, _ = harness.eval_report(run_dir, work, label, "--render-dir", "none", "--lpips-weights", lpips, env=env,
                                    program=(*MODULE, "fourierf_plugin.scripts.eval"))  # fmt: skip
    return {
        "label": label, "seed": seed, "train_wall_s": wall,
        "final_s_per_it": harness.seconds_per_iteration(harness.elapsed_by_step(records), *FINAL),
        "render_s": result["timings"]["render_seconds_total"], "psnr": result["results"]["psnr"],
    }  # fmt: skip


def time_iterations(code: Path, run_dir: Path, step: int = 700, warmup: int = 5, iters: int = 40) -> float:
    """Seconds per training iteration at ``step`` on a run's final saved state, in a fresh process of ``code``."""
    env = dict(os.environ, PYTHONPATH=str(code))
    cmd = [sys.executable, "-P", "-c", ITERATION_TIMER, str(run_dir), str(step), str(warmup), str(iters)]
    return float(subprocess.run(cmd, env=env, check=True, capture_output=True, text=True).stdout.split()[-1])


def summary(rows: list[dict], timings: dict[str, list[float]], meta: dict) -> list[str]:
    """The A/B as markdown: per side the medians, their new/old ratios, and each run's test PSNR."""
    runs = {side: sorted((r for r in rows if r["side"] == side), key=lambda r: r["label"]) for side in SIDES}

    def compared(name: str, old: list[float], new: list[float], digits: int) -> str:
        o, n = statistics.median(old), statistics.median(new)
        return f"| {name} | {o:.{digits}f} | {n:.{digits}f} | {n / o:.2f} |"

    extra = [f"{side}: `{shlex.join(meta[f'{side}_flags'])}`" for side in ("old", "new") if meta.get(f"{side}_flags")]
    lines = [
        (meta["describe"] or "old against new") + (f" (extra flags, {'; '.join(extra)})" if extra else ""),
        "",
        f"{meta['pairs']} interleaved pairs (seeds {', '.join(str(s) for s in meta['seeds'])}), alternating which side "
        "goes first; medians.",
        "",
        "| | old | new | new / old |",
        "|---|---|---|---|",
    ]
    for key, name, digits in (
        ("train_wall_s", "whole training run, s", 1),
        ("final_s_per_it", "final-phase s/iteration (steps 601–800)", 3),
        ("render_s", "render the test views, s", 2),
    ):
        old, new = ([r[key] for r in runs[side]] for side in SIDES)
        each = " · ".join(" / ".join(f"{v:.{digits}f}" for v in values) for values in (old, new))
        lines.append(compared(f"{name} ({each})", old, new, digits))
    repeats = f"{len(timings['old'])} alternating repeats of 40 per side"
    lines += [compared(f"s/iteration at step 700, in-process ({repeats})", timings["old"], timings["new"], 4), ""]
    for side in SIDES:
        psnrs = [f"{r['psnr']:.2f} (seed {r['seed']})" for r in rows if r["side"] == side]
        lines.append(f"- test PSNR {side}: " + ", ".join(psnrs))
    return lines


def write_report(work: Path, markdown: Path) -> None:
    """Write the BENCHMARKS.md section of the A/B recorded in ``work`` (results.jsonl, iterations.json, meta.json)."""
    if missing := [name for name in ("results.jsonl", "iterations.json", "meta.json") if not (work / name).is_file()]:
        sys.exit(f"error: no A/B recorded in {work} (missing {', '.join(missing)}); run the A/B first")
    timings, meta = (json.loads((work / name).read_text()) for name in ("iterations.json", "meta.json"))
    # a record without a scene is lego's
    title, marker = section_of(meta.get("scene", "lego"), bool(meta.get("old_flags") or meta.get("new_flags")))
    lines = summary(harness.read_jsonl(work / "results.jsonl"), timings, meta)
    harness.write_section(markdown, marker, "ab_speed.py", [*harness.section_head(title, meta["command"]), *lines, ""])


def main() -> None:
    ap = harness.arguments(__doc__, None)
    ap.add_argument("--old", default="HEAD", help="git revision of the baseline")
    ap.add_argument("--new", default=None, help="git revision to compare (default: the working tree)")
    ap.add_argument("--describe", default="", help="what differs between the sides (it goes into BENCHMARKS.md)")
    ap.add_argument("--old-flags", default="", help="training flags of the old side only (one string)")
    ap.add_argument("--new-flags", default="", help="training flags of the new side only (one string)")
    ap.add_argument("--pairs", type=int, default=3)
    ap.add_argument("--seeds", type=int, nargs="+", default=[20211202, 1, 2])
    ap.add_argument("--scene", choices=tuple(SCENES), default="lego")
    ap.add_argument("--iteration-repeats", type=int, default=6, help="alternating in-process timings per side")
    ap.add_argument("--report", action="store_true", help="only rewrite BENCHMARKS.md from the A/B recorded in --work")
    args = ap.parse_args()
    try:
        flags = {"old": shlex.split(args.old_flags), "new": shlex.split(args.new_flags)}
    except ValueError as err:
        ap.error(f"--old-flags / --new-flags: {err}; quote each side's flags as one shell string")
    args.work = args.work or harness.REPO / "outputs" / f"bench_{SCENES[args.scene]['marker']}"
    if args.report:
        return write_report(args.work, args.markdown)
    args.work.mkdir(parents=True, exist_ok=True)
    labels = {side: revision_label(rev) + (f" + {shlex.join(flags[side])}" if flags[side] else "")
              for side, rev in (("old", args.old), ("new", args.new))}  # fmt: skip
    codes = {"old": export_tree(args.old, args.work / "code-old"), "new": export_tree(args.new, args.work / "code-new")}
    rows, seeds = [], [args.seeds[i % len(args.seeds)] for i in range(args.pairs)]
    for i, side in harness.interleaved(args.pairs, SIDES):
        row = run_side(codes[side], f"{side}-{i}", seeds[i], args.work, args.shared, args.scene, flags[side])
        rows.append(row | {"side": side})
        print(json.dumps(rows[-1]), flush=True)
    harness.write_jsonl(args.work / "results.jsonl", rows)
    # The final phase again, with less noise: 40 iterations at step 700 on each side's own final state (equal seeds
    # train identically), in short processes alternating old, new, old, ...
    first = {side: args.work / "runs" / f"{side}-0" / args.scene / "fourierf-vm" / "run" for side in ("old", "new")}
    timings: dict[str, list[float]] = {"old": [], "new": []}
    for _, side in harness.interleaved(args.iteration_repeats, SIDES):
        timings[side].append(time_iterations(codes[side], first[side]))
    (args.work / "iterations.json").write_text(json.dumps(timings))
    meta = {
        "old": labels["old"], "new": labels["new"], "describe": args.describe, "pairs": args.pairs, "scene": args.scene,
        "old_flags": flags["old"], "new_flags": flags["new"], "seeds": seeds,
        "command": "python benchmarks/ab_speed.py " + shlex.join(sys.argv[1:]),
    }  # fmt: skip
    (args.work / "meta.json").write_text(json.dumps(meta))
    write_report(args.work, args.markdown)


if __name__ == "__main__":
    main()
