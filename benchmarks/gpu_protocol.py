"""The paper's protocols on a GPU: time, seconds per iteration, peak GPU memory and PSNR next to the paper's.

    python benchmarks/gpu_protocol.py                      # on a CUDA machine: lego and fern, ~10 min each (paper)
    python benchmarks/gpu_protocol.py --tiny --device cpu  # the same pipeline end to end at toy size (the test)

Protocols (paper, sec. 4): lego, 4 views (the official code's k-means picks 27 76 97 99) at 800×800, 10,000
iterations, batch 4096, grid 128³ → 300³, every test view; fern, 3 views (RegNeRF's) at 1/8 resolution with the
real-scene preset, 10,000 iterations, batch 4096. The paper reports about 10 minutes per 10k iterations on an RTX
4090, lego 22.41 dB and fern 20.97 dB. Each run is ``fourierf-train`` in a child process, then ``fourierf-eval``;
the final-phase seconds per iteration are read from the run's log (the last 20 % of the steps) and the peak GPU
memory from the trainer's closing record. Results go to ``--work/results.jsonl`` and a BENCHMARKS.md section.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

from harness import (
    BIN,
    REPO,
    done_record,
    elapsed_by_step,
    markers,
    read_metrics,
    run_timed,
    section_head,
    update_benchmarks_md,
)

BEGIN, END = markers("gpu-protocol", "gpu_protocol.py")
PAPER = {"lego": 22.41, "fern": 20.97}
SIZES = [
    "--max-num-iterations", "10000", "--pipeline.datamanager.rays-per-batch", "4096",
    "--pipeline.model.field.n-voxels-init", str(128**3), "--pipeline.model.field.n-voxels-final", str(300**3),
]  # fmt: skip
TINY = [
    "--max-num-iterations", "20", "--log-every", "5", "--pipeline.datamanager.rays-per-batch", "256",
    "--pipeline.model.field.n-voxels-init", "4096", "--pipeline.model.field.n-voxels-final", "13824",
]  # fmt: skip


def protocols(shared: Path, tiny: bool) -> dict[str, tuple[Path, list[str]]]:
    """Scene folder and the flags after it, per protocol."""
    if tiny:
        return {"lego": (REPO / "demo" / "lego_tiny", [])}
    lego = ["blender-data", "--downscale", "1", "--test-every", "1", "--view-ids", "27", "76", "97", "99"]
    return {
        "lego": (shared / "data/blender/lego", lego),
        "fern": (shared / "data/llff/fern", ["llff-data", "--num-views", "3"]),
    }


def run(name: str, scene: Path, parser: list[str], args: argparse.Namespace) -> dict:
    out = args.work / "runs" / name
    sizes = TINY if args.tiny else SIZES
    train = [str(BIN / "fourierf-train"), "fourierf-vm", "--data", str(scene), "--output-dir", str(out),
             "--timestamp", "run", "--device", args.device, *sizes, *parser]  # fmt: skip
    wall, rss, code = run_timed(train, args.work / f"{name}.train.log")
    if code != 0:
        raise RuntimeError(f"training failed; see {args.work / f'{name}.train.log'}")
    (run_dir,) = out.glob("*/fourierf-vm/run")
    records = read_metrics(run_dir / "metrics.jsonl")
    elapsed, done = elapsed_by_step(records), done_record(records) or {}
    steps = sorted(elapsed)
    tail = [s for s in steps if s >= 0.8 * steps[-1]]
    tail = tail if len(tail) > 1 else steps[-2:]
    s_per_it = (elapsed[tail[-1]] - elapsed[tail[0]]) / (tail[-1] - tail[0]) if len(tail) > 1 else None
    report = args.work / f"{name}.eval.json"
    evaluate = [str(BIN / "fourierf-eval"), "--load-config", str(run_dir / "config.json"), "--output-path",
                str(report), "--render-dir", "none", "--overwrite", "--device", args.device]  # fmt: skip
    if args.lpips is not None:
        evaluate += ["--lpips-weights", str(args.lpips)]
    _, _, code = run_timed(evaluate, args.work / f"{name}.eval.log")
    if code != 0:
        raise RuntimeError(f"evaluation failed; see {args.work / f'{name}.eval.log'}")
    results = json.loads(report.read_text())["results"]
    return {
        "protocol": name, "device": args.device, "tiny": args.tiny, "train_seconds": done.get("train_seconds"),
        "wall_seconds": wall, "final_s_per_it": s_per_it, "peak_gpu_gb": done.get("peak_device_memory_gb"),
        "peak_rss_gb": rss, "psnr": results["psnr"], "ssim": results["ssim"], "lpips": results.get("lpips"),
        "paper_psnr": PAPER.get(name),
    }  # fmt: skip


def table(rows: list[dict]) -> list[str]:
    def num(value: float | None, fmt: str) -> str:
        return "—" if value is None else format(value, fmt)

    lines = [
        "| protocol | device | train s | final-phase s/it | peak GPU GB | PSNR | paper PSNR | SSIM | LPIPS |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    for r in rows:
        lines.append(
            f"| {r['protocol']}{' (tiny)' if r['tiny'] else ''} | {r['device']} | {num(r['train_seconds'], '.0f')} | "
            f"{num(r['final_s_per_it'], '.3f')} | {num(r['peak_gpu_gb'], '.2f')} | {r['psnr']:.2f} | "
            f"{num(r['paper_psnr'], '.2f')} | {r['ssim']:.3f} | {num(r['lpips'], '.3f')} |"
        )
    return lines


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--shared", type=Path, default=REPO.parent / "shared")
    ap.add_argument("--work", type=Path, default=REPO / "outputs" / "bench_gpu_protocol")
    ap.add_argument("--device", default="cuda", choices=["cuda", "cpu", "auto"])
    ap.add_argument("--tiny", action="store_true", help="the bundled scene at toy size (checks the pipeline)")
    ap.add_argument("--lpips", type=Path, default=None, help="LPIPS-alex weights (default: none)")
    ap.add_argument("--markdown", type=Path, default=REPO / "BENCHMARKS.md", help="'none' skips it")
    args = ap.parse_args()
    if args.device == "cuda":
        import torch

        if not torch.cuda.is_available():
            sys.exit("error: no CUDA device here; run on a GPU machine (or --tiny --device cpu to check the script)")
    args.work.mkdir(parents=True, exist_ok=True)
    rows = [run(name, scene, parser, args) for name, (scene, parser) in protocols(args.shared, args.tiny).items()]
    (args.work / "results.jsonl").write_text("".join(json.dumps(r) + "\n" for r in rows))
    lines = table(rows)
    print("\n".join(lines))
    if str(args.markdown).lower() != "none":
        head = section_head("The paper's protocols on a GPU", "python benchmarks/gpu_protocol.py")
        update_benchmarks_md(args.markdown, BEGIN, END, [*head, *lines])


if __name__ == "__main__":
    main()
