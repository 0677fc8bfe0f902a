"""P-CPU against the official FourieRF code, in one invocation: reference and this project interleaved, seed by seed.

    ../shared/peer/setup.sh                                  # once: the reference's virtualenv
    python benchmarks/pcpu_vs_reference.py                   # 3 seeds, ~35 minutes on 2 cores; keep the machine quiet
    python benchmarks/pcpu_vs_reference.py --report-only     # rebuild the BENCHMARKS.md section from results.jsonl

Protocol P-CPU for both: lego 4 views (r_27 r_76 r_97 r_99), 100×100, batch 1024, grid 64³ → 128³, 800 iterations,
the official optimiser (no weight decay, no lr decay), 25 test views. The reference runs through
``../shared/peer/run_pcpu.sh fourierf SEED`` (the official code with CPU patches; its training loop time, final-phase
seconds per iteration and test PSNR); this project through ``fourierf-train`` with a checkpoint every 10 % of the run,
each evaluated on the test views afterwards (not timed), so its PSNR along training is known. Each pair alternates
which side goes first. Ratios come from these pairs only:

* time to the reference's quality: the reference's training time divided by the seconds this project's training took
  until its test PSNR first reached the reference's final PSNR. The reference is not evaluated along training, so its
  own time to that PSNR is taken as its whole run: if it got there earlier, the true ratio is smaller (an upper
  bound);
* per iteration: final-phase seconds per iteration (iterations 601-800) of the reference over ours;
* per run: training time of the reference over ours; and the final PSNR difference and peak RSS.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
from pathlib import Path

from harness import (
    BIN,
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

BEGIN, END = markers("pcpu-vs-reference", "pcpu_vs_reference.py")
EVAL_EVERY = 80  # 10 % of the run
assert GRID_FLAGS[-2] == "--steps-per-save", "GRID_FLAGS ends with its own save interval, replaced here"


def reference_run(peer: Path, seed: int, log: Path) -> dict:
    """One reference run; the fields of its RESULT line as numbers."""
    env = dict(os.environ, PCPU_OUT=str(log.parent / "peer-runs"))
    proc = subprocess.run(
        ["bash", str(peer / "run_pcpu.sh"), "fourierf", str(seed)], capture_output=True, text=True, env=env
    )
    log.write_text(proc.stdout + proc.stderr)
    lines = [line for line in proc.stdout.splitlines() if line.startswith("RESULT ")]
    if proc.returncode != 0 or not lines:
        raise RuntimeError(f"the reference run failed; see {log}")
    fields = dict(item.split("=", 1) for item in lines[-1].split()[1:])
    return {k: float(v) for k, v in fields.items() if k not in ("method", "seed")}


def our_run(shared: Path, seed: int, work: Path) -> dict:
    """One run of this project, then every saved checkpoint scored on the test views (after, untimed)."""
    out = work / "runs" / f"ours-{seed}"
    train = [
        str(BIN / "fourierf-train"), "fourierf-vm", "--data", str(shared / "data/blender/lego"),
        "--output-dir", str(out), "--timestamp", "run", "--seed", str(seed), "--max-num-iterations", "800",
        *GRID_FLAGS[:-2], "--steps-per-save", str(EVAL_EVERY), "--keep-checkpoints", "0",
        "--log-every", str(EVAL_EVERY // 2),
        *OFFICIAL_OPTIMISER, *PCPU_LEGO_PARSER,
    ]  # fmt: skip
    _, rss, code = run_timed(train, work / f"ours-{seed}.train.log")
    if code != 0:
        raise RuntimeError(f"training failed; see {work / f'ours-{seed}.train.log'}")
    run_dir = out / "lego" / "fourierf-vm" / "run"
    records = read_metrics(run_dir / "metrics.jsonl")
    elapsed = elapsed_by_step(records)
    curve = {}
    for ckpt in sorted((run_dir / "checkpoints").glob("step-*.ckpt")):
        step = int(ckpt.stem.split("-")[1])
        report = work / f"ours-{seed}.step{step}.json"
        cmd = [
            str(BIN / "fourierf-eval"), "--load-config", str(run_dir / "config.json"), "--checkpoint", str(ckpt),
            "--output-path", str(report), "--render-dir", "none", "--overwrite", "--lpips-weights",
            str(shared / "lpips/lpips_alex_v0.1.pth"),
        ]  # fmt: skip
        if run_timed(cmd, work / f"ours-{seed}.eval.log")[2] != 0:
            raise RuntimeError(f"evaluation failed; see {work / f'ours-{seed}.eval.log'}")
        curve[step] = json.loads(report.read_text())["results"]["psnr"]
    done = next(r for r in reversed(records) if r.get("event") == "done")
    return {
        "train_wall_s": done["train_seconds"],
        "final_phase_s_per_it": (elapsed[800] - elapsed[600]) / 200,
        "test_psnr": curve[800],
        "peak_rss_gb": rss,
        "psnr_curve": curve,
        "elapsed": {step: elapsed[step] for step in curve},
    }


def seconds_to(curve: dict, elapsed: dict, target: float) -> float | None:
    """Training seconds at the first evaluated step whose PSNR reaches ``target`` (None: never)."""
    for step in sorted(curve, key=int):
        if curve[step] >= target:
            return elapsed[step]
    return None


def report(rows: list[dict]) -> list[str]:
    lines = [
        "| seed | reference train s | ours train s | ours s to ref PSNR | time-to-quality × | per-iteration × | "
        "per-run × | ref PSNR | ours PSNR | Δ dB | ref / ours peak RSS GB |",
        "|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    ratios = {"quality": [], "iteration": [], "run": [], "psnr": []}
    for r in rows:
        ref, ours = r["reference"], r["ours"]
        reach = seconds_to(ours["psnr_curve"], ours["elapsed"], ref["test_psnr"])
        quality = ref["train_wall_s"] / reach if reach else None
        iteration = ref["final_phase_s_per_it"] / ours["final_phase_s_per_it"]
        run = ref["train_wall_s"] / ours["train_wall_s"]
        delta = ours["test_psnr"] - ref["test_psnr"]
        for key, value in (("quality", quality), ("iteration", iteration), ("run", run), ("psnr", delta)):
            if value is not None:
                ratios[key].append(value)
        lines.append(
            f"| {r['seed']} | {ref['train_wall_s']:.0f} | {ours['train_wall_s']:.0f} | "
            f"{'never' if reach is None else f'{reach:.0f}'} | {'—' if quality is None else f'{quality:.2f}'} | "
            f"{iteration:.2f} | {run:.2f} | {ref['test_psnr']:.2f} | {ours['test_psnr']:.2f} | {delta:+.2f} | "
            f"{ref['peak_rss_gb']:.2f} / {ours['peak_rss_gb']:.2f} |"
        )
    med = {k: statistics.median(v) for k, v in ratios.items() if v}
    lines += [
        "",
        f"Medians over {len(rows)} pairs: time to the reference's final PSNR "
        f"**{med.get('quality', float('nan')):.2f}×** faster (an upper bound: the reference's own time to it is taken "
        "as its whole run), per iteration "
        f"{med['iteration']:.2f}×, per run {med['run']:.2f}×, PSNR "
        f"{med['psnr']:+.2f} dB.",
    ]
    return lines


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--shared", type=Path, default=REPO.parent / "shared")
    ap.add_argument("--work", type=Path, default=REPO / "outputs" / "bench_pcpu_vs_reference")
    ap.add_argument("--seeds", type=int, nargs="+", default=[20211202, 1, 2])
    ap.add_argument("--markdown", type=Path, default=REPO / "BENCHMARKS.md")
    ap.add_argument("--report-only", action="store_true")
    args = ap.parse_args()
    args.work.mkdir(parents=True, exist_ok=True)
    results = args.work / "results.jsonl"
    rows = [json.loads(line) for line in results.read_text().splitlines()] if results.exists() else []
    done = {r["seed"] for r in rows}
    peer = args.shared / "peer"
    if not args.report_only:
        if not (peer / "run_pcpu.sh").is_file():
            sys.exit(f"error: {peer} has no run_pcpu.sh; pass --shared PATH_TO_SHARED")
        for i, seed in enumerate(s for s in args.seeds if s not in done):
            row: dict = {"seed": seed}
            for side in ("reference", "ours") if i % 2 == 0 else ("ours", "reference"):
                print(f"seed {seed}: {side} ...", flush=True)
                if side == "reference":
                    row[side] = reference_run(peer, seed, args.work / f"reference-{seed}.log")
                else:
                    row[side] = our_run(args.shared, seed, args.work)
            rows.append(row)
            with results.open("a") as fh:
                fh.write(json.dumps(row) + "\n")
    body = [
        *section_head(
            "P-CPU against the official code, interleaved in one invocation",
            "python benchmarks/pcpu_vs_reference.py",
            "Both sides: lego 4 views, 100×100, batch 1024, 64³ → 128³, 800 iterations, the official optimiser; "
            "reference = ../shared/peer (official code, CPU patches). Ratios are reference / ours from the same pair.",
        ),
        *report(rows),
    ]
    print("\n".join(body))
    if str(args.markdown).lower() != "none":
        update_benchmarks_md(args.markdown, BEGIN, END, body)


if __name__ == "__main__":
    main()
