"""The paper's lego and fern protocols (sec. 4: 10,000 iterations, batch 4096, grid 128³ → 300³) on a GPU: time,
final-phase seconds per iteration, peak GPU memory and PSNR next to the paper's.

    python benchmarks/gpu_protocol.py                      # on a CUDA machine: lego and fern
    python benchmarks/gpu_protocol.py --tiny --device cpu  # the same pipeline end to end at toy size (the test)
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import harness

PAPER = {"lego": 22.41, "fern": 20.97}
SIZES = ["--max-num-iterations", "10000", *harness.size_flags(4096, (128, 300))]
TINY = ["--max-num-iterations", "20", "--log-every", "5", *harness.size_flags(256, (16, 24))]
DIGITS = {"train_seconds": 0, "final_s_per_it": 3, "peak_gpu_gb": 2, "psnr": 2, "paper_psnr": 2, "ssim": 3, "lpips": 3}


def protocols(shared: Path, tiny: bool) -> dict[str, tuple[Path, list[str]]]:
    """Scene folder and the flags after it, per protocol."""
    if tiny:
        return {"lego": (harness.REPO / "demo" / "lego_tiny", [])}
    return {
        "lego": (shared / "data/blender/lego", ["blender-data", "--downscale", "1", "--test-every", "1", "--view-ids",
                                                *harness.LEGO_VIEWS]),
        "fern": (shared / "data/llff/fern", ["llff-data", "--num-views", "3"]),
    }  # fmt: skip


def run(name: str, scene: Path, parser: list[str], args: argparse.Namespace) -> dict:
    device, sizes = ["--device", args.device], TINY if args.tiny else SIZES
    run_dir, records, wall, rss = harness.train_run(scene, args.work, name, *device, *sizes, *parser)
    elapsed, done = harness.elapsed_by_step(records), harness.done_record(records) or {}
    steps = sorted(elapsed)
    tail = [s for s in steps if s >= 0.8 * steps[-1]]
    tail = tail if len(tail) > 1 else steps[-2:]
    s_per_it = harness.seconds_per_iteration(elapsed, tail[0], tail[-1]) if len(tail) > 1 else None
    lpips = [] if args.lpips is None else ["--lpips-weights", str(args.lpips)]
    results = harness.eval_report(run_dir, args.work, name, "--render-dir", "none", *device, *lpips)[0]["results"]
    return {
        "protocol": name, "device": args.device, "tiny": args.tiny, "train_seconds": done.get("train_seconds"),
        "wall_seconds": wall, "final_s_per_it": s_per_it, "peak_gpu_gb": done.get("peak_device_memory_gb"),
        "peak_rss_gb": rss, "psnr": results["psnr"], "ssim": results["ssim"], "lpips": results.get("lpips"),
        "paper_psnr": PAPER.get(name),
    }  # fmt: skip


def section(rows: list[dict]) -> list[str]:
    lines = harness.section_head("The paper's protocols on a GPU", "python benchmarks/gpu_protocol.py")
    head = ["protocol", "device", "train s", "final-phase s/it", "peak GPU GB", "PSNR", "paper PSNR", "SSIM", "LPIPS"]
    cells = []
    for r in rows:  # a value not measured (a CPU run's GPU memory, the paper's PSNR of a tiny run) is a dash
        measured = ["—" if r[k] is None else f"{r[k]:.{d}f}" for k, d in DIGITS.items()]
        cells.append(harness.md_row([r["protocol"] + (" (tiny)" if r["tiny"] else ""), r["device"], *measured]))
    return lines + harness.table(head, cells)


def main() -> None:
    ap = harness.arguments(__doc__, "bench_gpu_protocol")
    ap.add_argument("--device", default="cuda", choices=["cuda", "cpu", "auto"])
    ap.add_argument("--tiny", action="store_true", help="the bundled scene at toy size (checks the pipeline)")
    ap.add_argument("--lpips", type=Path, default=None, help="LPIPS-alex weights (default: none)")
    args = ap.parse_args()
    if args.device == "cuda":
        import torch

        if not torch.cuda.is_available():
            sys.exit("error: no CUDA device here; run on a GPU machine (or --tiny --device cpu to check the script)")
    rows = [run(name, scene, parser, args) for name, (scene, parser) in protocols(args.shared, args.tiny).items()]
    harness.write_jsonl(args.work / "results.jsonl", rows)
    harness.write_section(args.markdown, "gpu-protocol", "gpu_protocol.py", section(rows))


if __name__ == "__main__":
    main()
