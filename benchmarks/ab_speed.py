"""Interleaved A/B of two versions of fourierf on protocol P-CPU: is the new one as fast as the old one?

Each version is exported into its own flat folder (the package with ``method_configs`` and ``data/parsers`` put in
their installed places) and run from there with ``python -m fourierf_plugin.scripts.train`` / ``.eval``, so both
sides run in this one invocation on this machine, alternating which goes first in each pair:

    python benchmarks/ab_speed.py --old HEAD            # the working tree against the last commit, 3 pairs
    python benchmarks/ab_speed.py --old abc123 --new def456 --pairs 5
    python benchmarks/ab_speed.py --old HEAD --new HEAD --new-flags "--pipeline.model.entropy-weight 0.00003"

The last form times an option rather than a change: one version, the new side trained with extra flags (each side's
flags go before the data parser's), reported in a section of its own so a default change's A/B stays.

P-CPU: lego 4 views (r_27 r_76 r_97 r_99), 100×100, batch 1024, grid 64³ → 128³, 800 iterations, the official code's
optimiser (weight decay 0, no lr decay), 25 test views; or, with ``--scene fern``, fern 3 views at images_8 on the same
grid, batch and budget under the real-scene preset (a change to a forward-facing default). Reported per side: the
median final-phase seconds per iteration (iterations 601–800, from the runs' own logs, no profiler) and the median
time to render the test views (``fourierf-eval``'s render seconds), the new/old ratios, and the test PSNR of each run
(equal seeds must give equal PSNRs when the arithmetic did not change). Takes about 4 minutes per run on two cores;
keep the machine quiet. Each scene has its own BENCHMARKS.md section, which says what differs between the sides
(``--describe`` and any side's extra flags); the revisions each side ran are recorded in ``--work``'s meta.json.
"""

from __future__ import annotations

import argparse
import json
import os
import shlex
import shutil
import statistics
import subprocess
import sys
from collections.abc import Sequence
from dataclasses import dataclass, replace
from pathlib import Path

from harness import (
    GRID_FLAGS,
    OFFICIAL_OPTIMISER,
    PCPU_LEGO_PARSER,
    REPO,
    elapsed_by_step,
    markers,
    read_metrics,
    run_timed,
    section_head,
    update_benchmarks_md,
)

SOURCES = ("fourierf_plugin", "method_configs", "data/parsers")
INSTALLED = {"method_configs": "fourierf_plugin/method_configs", "data/parsers": "fourierf_plugin/data/parsers"}


@dataclass(frozen=True)
class Scene:
    data: str
    """The scene folder under ``<shared>/data``."""
    flags: tuple[str, ...]
    """Method flags beyond P-CPU's sizes."""
    parser: tuple[str, ...]
    title: str
    """The BENCHMARKS.md section's title."""
    marker: str

    @property
    def name(self) -> str:
        return Path(self.data).name

    def for_option(self) -> Scene:
        """The same scene, reporting into a section of its own: an option's cost, not a change to a default."""
        return replace(self, title=f"Cost of an option on P-CPU {self.name} (interleaved A/B of flags)",
                       marker=f"{self.marker}_option")  # fmt: skip

    @property
    def begin(self) -> str:
        return markers(self.marker, "ab_speed.py")[0]

    @property
    def end(self) -> str:
        return markers(self.marker, "ab_speed.py")[1]


SCENES = {
    "lego": Scene(
        "blender/lego", tuple(OFFICIAL_OPTIMISER),
        tuple(PCPU_LEGO_PARSER),
        "Speed A/B of a change to a default (lego, interleaved)", "ab_speed",
    ),
    "fern": Scene(
        "llff/fern", (), ("llff-data", "--num-views", "3"),
        "Speed A/B of a change to a forward-facing default (fern, interleaved)", "ab_speed_fern",
    ),
}  # fmt: skip
BEGIN, END = SCENES["lego"].begin, SCENES["lego"].end
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


def revision_label(rev: str | None) -> str:
    """What a side ran, for meta.json: ``rev`` with its short commit id, or the working tree on its commit, marked when
    it held uncommitted changes."""
    head = subprocess.run(
        ["git", "rev-parse", "--short", rev or "HEAD"], cwd=REPO, check=True, capture_output=True, text=True
    ).stdout.strip()
    if rev is not None:
        return rev if rev.startswith(head) else f"{rev} ({head})"
    dirty = subprocess.run(
        ["git", "status", "--porcelain", "--untracked-files=no", *SOURCES], cwd=REPO, check=True, capture_output=True,
        text=True,
    ).stdout.strip()  # fmt: skip
    return f"the working tree on {head}" + (", with uncommitted changes" if dirty else "")


def run_side(
    code: Path, label: str, seed: int, work: Path, shared: Path, scene: Scene, flags: Sequence[str] = ()
) -> dict:
    """Train and evaluate one P-CPU run of ``scene`` with the package in ``code`` and the side's own ``flags``; its
    timings and PSNR."""
    env = dict(os.environ, PYTHONPATH=str(code))
    out = work / "runs" / label
    shutil.rmtree(out, ignore_errors=True)
    train = [
        sys.executable, "-P", "-m", "fourierf_plugin.scripts.train", "fourierf-vm",
        "--data", str(shared / "data" / scene.data), "--output-dir", str(out), "--timestamp", "run",
        "--seed", str(seed), "--max-num-iterations", "800",
        "--log-every", "50", *GRID_FLAGS, *scene.flags, *flags, *scene.parser,
    ]  # fmt: skip
    wall, _, code_ = run_timed(train, work / f"{label}.train.log", env)
    if code_ != 0:
        raise RuntimeError(f"training failed; see {work / f'{label}.train.log'}")
    run_dir = out / scene.name / "fourierf-vm" / "run"
    elapsed = elapsed_by_step(read_metrics(run_dir / "metrics.jsonl"))
    report = work / f"{label}.eval.json"
    evaluate = [
        sys.executable, "-P", "-m", "fourierf_plugin.scripts.eval", "--load-config", str(run_dir / "config.json"),
        "--output-path", str(report), "--render-dir", "none", "--overwrite",
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


def summary(rows: list[dict], timings: dict[str, list[float]], meta: dict) -> list[str]:
    """The A/B as markdown: whole runs, the final phase, in-process iterations and renders per side (medians), their
    new/old ratios, and each run's test PSNR."""

    def med(side: str, key: str) -> float:
        return statistics.median(r[key] for r in rows if r["side"] == side)

    def each(side: str, key: str, digits: int) -> str:
        return " / ".join(f"{r[key]:.{digits}f}" for r in sorted(rows, key=lambda r: r["label"]) if r["side"] == side)

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
        lines.append(
            f"| {name} ({each('old', key, digits)} · {each('new', key, digits)}) | {med('old', key):.{digits}f} | "
            f"{med('new', key):.{digits}f} | {med('new', key) / med('old', key):.2f} |"
        )
    old_it, new_it = statistics.median(timings["old"]), statistics.median(timings["new"])
    lines.append(
        f"| s/iteration at step 700, in-process ({len(timings['old'])} alternating repeats of 40 per side) | "
        f"{old_it:.4f} | {new_it:.4f} | {new_it / old_it:.2f} |"
    )
    lines.append("")
    for side in ("old", "new"):
        psnrs = [f"{r['psnr']:.2f} (seed {r['seed']})" for r in rows if r["side"] == side]
        lines.append(f"- test PSNR {side}: " + ", ".join(psnrs))
    return lines


def write_report(work: Path, markdown: Path) -> list[str]:
    """The BENCHMARKS.md section of the A/B recorded in ``work`` (results.jsonl, iterations.json, meta.json)."""
    names = ("results.jsonl", "iterations.json", "meta.json")
    missing = [name for name in names if not (work / name).is_file()]
    if missing:
        sys.exit(f"error: no A/B recorded in {work} (missing {', '.join(missing)}); run the A/B first")
    rows = [json.loads(line) for line in (work / "results.jsonl").read_text().splitlines() if line.strip()]
    timings = json.loads((work / "iterations.json").read_text())
    meta = json.loads((work / "meta.json").read_text())
    scene = SCENES[meta.get("scene", "lego")]  # records before --scene were lego's
    if meta.get("old_flags") or meta.get("new_flags"):
        scene = scene.for_option()
    lines = summary(rows, timings, meta)
    body = section_head(scene.title, meta["command"])
    update_benchmarks_md(markdown, scene.begin, scene.end, [*body, *lines, ""])
    return lines


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--old", default="HEAD", help="git revision of the baseline")
    ap.add_argument("--new", default=None, help="git revision to compare (default: the working tree)")
    ap.add_argument("--describe", default="",
                    help="what differs between the sides, without history: it goes into BENCHMARKS.md")  # fmt: skip
    ap.add_argument("--old-flags", default="", help="training flags of the old side only (one string)")
    ap.add_argument("--new-flags", default="", help="training flags of the new side only (one string)")
    ap.add_argument("--pairs", type=int, default=3)
    ap.add_argument("--seeds", type=int, nargs="+", default=[20211202, 1, 2])
    ap.add_argument("--shared", type=Path, default=REPO.parent / "shared")
    ap.add_argument("--scene", choices=tuple(SCENES), default="lego")
    ap.add_argument("--work", type=Path, default=None, help="default: outputs/bench_ab_speed (lego), ..._fern (fern)")
    ap.add_argument("--iteration-repeats", type=int, default=6, help="alternating in-process timings per side")
    ap.add_argument("--markdown", type=Path, default=REPO / "BENCHMARKS.md")
    ap.add_argument("--report", action="store_true", help="only rewrite BENCHMARKS.md from the A/B recorded in --work")
    args = ap.parse_args()
    scene = SCENES[args.scene]
    try:
        flags = {"old": shlex.split(args.old_flags), "new": shlex.split(args.new_flags)}
    except ValueError as err:
        ap.error(f"--old-flags / --new-flags: {err}; quote each side's flags as one shell string")
    if args.work is None:
        args.work = REPO / "outputs" / ("bench_ab_speed" if args.scene == "lego" else f"bench_ab_speed_{args.scene}")
    if args.report:
        print("\n".join(write_report(args.work, args.markdown)))
        return
    args.work.mkdir(parents=True, exist_ok=True)
    labels = {side: revision_label(rev) + (f" + {shlex.join(flags[side])}" if flags[side] else "")
              for side, rev in (("old", args.old), ("new", args.new))}  # fmt: skip
    codes = {"old": export_tree(args.old, args.work / "code-old"), "new": export_tree(args.new, args.work / "code-new")}
    rows = []
    for i in range(args.pairs):
        seed = args.seeds[i % len(args.seeds)]
        order = ("old", "new") if i % 2 == 0 else ("new", "old")
        for side in order:
            row = run_side(codes[side], f"{side}-{i}", seed, args.work, args.shared, scene, flags[side])
            row |= {"side": side}
            rows.append(row)
            print(json.dumps(row), flush=True)
    (args.work / "results.jsonl").write_text("".join(json.dumps(r) + "\n" for r in rows))
    # The final phase again, with less noise: 40 iterations at step 700 on each side's own final state (the same
    # state: equal seeds train identically), in short processes alternating old, new, old, ...
    first = {side: args.work / "runs" / f"{side}-0" / scene.name / "fourierf-vm" / "run" for side in ("old", "new")}
    timings: dict[str, list[float]] = {"old": [], "new": []}
    for i in range(args.iteration_repeats):
        for side in ("old", "new") if i % 2 == 0 else ("new", "old"):
            timings[side].append(time_iterations(codes[side], first[side]))
    (args.work / "iterations.json").write_text(json.dumps(timings))
    meta = {
        "old": labels["old"], "new": labels["new"], "describe": args.describe, "pairs": args.pairs, "scene": args.scene,
        "old_flags": flags["old"], "new_flags": flags["new"],
        "seeds": [args.seeds[i % len(args.seeds)] for i in range(args.pairs)],
        "command": "python benchmarks/ab_speed.py " + shlex.join(sys.argv[1:]),
    }  # fmt: skip
    (args.work / "meta.json").write_text(json.dumps(meta))
    print("\n".join(write_report(args.work, args.markdown)))


if __name__ == "__main__":
    main()
