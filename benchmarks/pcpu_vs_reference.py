"""P-CPU against the official FourieRF code (``../shared/peer``, CPU patches), interleaved seed by seed: ratios of
time to the reference's final PSNR (ours scored every 10 % of the run, untimed), per iteration and per run.

    ../shared/peer/setup.sh                  # once: the reference's virtualenv
    python benchmarks/pcpu_vs_reference.py   # runs the seeds not yet recorded, then writes the section
"""

from __future__ import annotations

import os
import statistics
import subprocess
import sys
from pathlib import Path

import harness

EVAL_EVERY = 80  # 10 % of the run


def reference_run(shared: Path, seed: int, work: Path) -> dict:
    """One reference run (its log ``work/reference-SEED.log``); the fields of its RESULT line as numbers."""
    log, env = work / f"reference-{seed}.log", dict(os.environ, PCPU_OUT=str(work / "peer-runs"))
    cmd = ["bash", str(shared / "peer" / "run_pcpu.sh"), "fourierf", str(seed)]
    proc = subprocess.run(cmd, capture_output=True, text=True, env=env)
    log.write_text(proc.stdout + proc.stderr)
    lines = [line for line in proc.stdout.splitlines() if line.startswith("RESULT ")]
    if proc.returncode != 0 or not lines:
        raise RuntimeError(f"the reference run failed; see {log}")
    fields = dict(item.split("=", 1) for item in lines[-1].split()[1:])
    return {k: float(v) for k, v in fields.items() if k not in ("method", "seed")}


def our_run(shared: Path, seed: int, work: Path) -> dict:
    """One run of this project, then every saved checkpoint scored on the test views (after, untimed)."""
    lpips = str(shared / harness.LPIPS)
    flags = [
        "--seed", str(seed), "--max-num-iterations", "800", *harness.GRID_FLAGS, "--steps-per-save", str(EVAL_EVERY),
        "--keep-checkpoints", "0", "--log-every", str(EVAL_EVERY // 2), *harness.OFFICIAL_OPTIMISER,
        *harness.PCPU_LEGO_PARSER,
    ]  # fmt: skip
    run_dir, records, _, rss = harness.train_run(shared / "data/blender/lego", work, f"ours-{seed}", *flags)
    elapsed = harness.elapsed_by_step(records)
    curve = {}
    for ckpt in sorted((run_dir / "checkpoints").glob("step-*.ckpt")):
        step = int(ckpt.stem.split("-")[1])
        flags = ["--checkpoint", str(ckpt), "--render-dir", "none", "--lpips-weights", lpips]
        curve[step] = harness.eval_report(run_dir, work, f"ours-{seed}.step{step}", *flags)[0]["results"]["psnr"]
    return {
        "train_wall_s": harness.done_record(records)["train_seconds"],  # type: ignore[index]
        "final_phase_s_per_it": harness.seconds_per_iteration(elapsed, 600, 800), "test_psnr": curve[800],
        "peak_rss_gb": rss, "psnr_curve": curve, "elapsed": {step: elapsed[step] for step in curve},
    }  # fmt: skip


def section(rows: list[dict]) -> list[str]:
    """Per seed the ratios reference / ours (time to the reference's PSNR, per iteration, per run); their medians."""
    lines = [
        *harness.section_head(
            "P-CPU against the official code, interleaved in one invocation",
            "python benchmarks/pcpu_vs_reference.py",
            "Both sides: lego 4 views, 100×100, batch 1024, 64³ → 128³, 800 iterations, the official optimiser; "
            "reference = ../shared/peer (official code, CPU patches). Ratios are reference / ours from the same pair.",
        ),
        "| seed | reference train s | ours train s | ours s to ref PSNR | time-to-quality × | per-iteration × | "
        "per-run × | ref PSNR | ours PSNR | Δ dB | ref / ours peak RSS GB |",
        "|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    pairs: list[dict[str, float | None]] = []  # per pair: the ratios and the PSNR difference
    for r in rows:
        ref, ours = r["reference"], r["ours"]
        curve = ours["psnr_curve"]  # training seconds at the first evaluated step reaching the reference's PSNR:
        reach = next((ours["elapsed"][s] for s in sorted(curve, key=int) if curve[s] >= ref["test_psnr"]), None)
        quality = ref["train_wall_s"] / reach if reach else None
        iteration = ref["final_phase_s_per_it"] / ours["final_phase_s_per_it"]
        run = ref["train_wall_s"] / ours["train_wall_s"]
        delta = ours["test_psnr"] - ref["test_psnr"]
        pairs.append({"quality": quality, "iteration": iteration, "run": run, "psnr": delta})
        lines.append(
            f"| {r['seed']} | {ref['train_wall_s']:.0f} | {ours['train_wall_s']:.0f} | "
            f"{'never' if reach is None else f'{reach:.0f}'} | {'—' if quality is None else f'{quality:.2f}'} | "
            f"{iteration:.2f} | {run:.2f} | {ref['test_psnr']:.2f} | {ours['test_psnr']:.2f} | {delta:+.2f} | "
            f"{ref['peak_rss_gb']:.2f} / {ours['peak_rss_gb']:.2f} |"
        )
    med = {k: statistics.median(v) for k in pairs[0] if (v := [p[k] for p in pairs if p[k] is not None])}
    return [
        *lines,
        "",
        f"Medians over {len(rows)} pairs: time to the reference's final PSNR "
        f"**{med.get('quality', float('nan')):.2f}×** faster (an upper bound: the reference's own time to it is taken "
        f"as its whole run), per iteration {med['iteration']:.2f}×, per run {med['run']:.2f}×, PSNR "
        f"{med['psnr']:+.2f} dB.",
    ]


def main() -> None:
    ap = harness.arguments(__doc__, "bench_pcpu_vs_reference")
    ap.add_argument("--seeds", type=int, nargs="+", default=[20211202, 1, 2])
    args = ap.parse_args()
    args.work.mkdir(parents=True, exist_ok=True)
    results, peer = args.work / "results.jsonl", args.shared / "peer"
    rows = harness.read_jsonl(results)
    todo = [s for s in args.seeds if s not in {r["seed"] for r in rows}]
    if todo and not (peer / "run_pcpu.sh").is_file():
        sys.exit(f"error: {peer} has no run_pcpu.sh; pass --shared PATH_TO_SHARED")
    for i, seed in enumerate(todo):
        row: dict = {"seed": seed}
        for side in ("reference", "ours") if i % 2 == 0 else ("ours", "reference"):
            print(f"seed {seed}: {side} ...", flush=True)
            row[side] = {"ours": our_run, "reference": reference_run}[side](args.shared, seed, args.work)
        rows.append(row)
        harness.write_jsonl(results, rows)
    harness.write_section(args.markdown, "pcpu-vs-reference", "pcpu_vs_reference.py", section(rows))


if __name__ == "__main__":
    main()
