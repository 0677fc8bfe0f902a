"""``fourierf-eval --load-config RUN/config.json --output-path eval.json``: metrics on held-out views."""

from __future__ import annotations

import json
import sys
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Literal

import imageio.v3 as iio
import numpy as np
import torch
import tyro
from rich.markup import escape

from fourierf_plugin.engine.loading import load_run
from fourierf_plugin.engine.run_dir import unique_safe_name
from fourierf_plugin.utils.console import get_console, warn
from fourierf_plugin.utils.errors import fail, run_cli, strip_verbose
from fourierf_plugin.utils.lpips import LPIPS, default_lpips_weights
from fourierf_plugin.utils.metrics import mean_and_std, psnr, ssim


@dataclass
class EvalConfig:
    load_config: Path
    """config.json of a training run."""
    output_path: Path = Path("eval.json")
    """Where to write the metrics JSON."""
    split: Literal["test", "val", "train"] = "test"
    """Which views to evaluate (tune on val, report on test)."""
    checkpoint: Path | None = None
    """A specific checkpoint (default: the run's latest)."""
    lpips_weights: Path | None = None
    """LPIPS-alex v0.1 weights (default: $FOURIERF_LPIPS_WEIGHTS or ../shared/lpips)."""
    render_dir: Path | None = None
    """Where to save the rendered images (default: RUN/renders/<split>-step<N>/; 'none' skips)."""
    device: Literal["auto", "cpu", "cuda"] = "auto"
    data: Path | None = None
    """Override the scene folder recorded in the config (e.g. the run was made on another machine)."""


def to_png(image: torch.Tensor) -> np.ndarray:
    return (image.clamp(0, 1).numpy() * 255.0 + 0.5).astype(np.uint8)


def evaluate(cfg: EvalConfig) -> dict:
    console = get_console()
    run = load_run(cfg.load_config, cfg.checkpoint, cfg.device, cfg.data)
    train_cfg, pipeline, step, ckpt_path, run_dir, device = (
        run.config,
        run.pipeline,
        run.step,
        run.checkpoint,
        run.run_dir,
        run.device,
    )

    weights = cfg.lpips_weights or default_lpips_weights()
    lpips = LPIPS(weights).to(device) if weights is not None else None
    if lpips is None:
        warn("LPIPS weights not found; LPIPS is skipped (pass --lpips-weights PATH to include it)")

    render_dir = cfg.render_dir or run_dir / "renders" / f"{cfg.split}-step{step:06d}"
    save_images = str(render_dir).lower() != "none"
    if save_images:
        render_dir.mkdir(parents=True, exist_ok=True)

    per_image = []
    stems: set[str] = set()  # names from the dataset, made safe and distinct as file names
    started = time.perf_counter()
    for index, r in enumerate(pipeline.render_views(cfg.split, step)):
        item = {
            "name": r.view.name,
            "view_id": r.view.view_id,
            "psnr": psnr(r.rgb, r.target),
            "ssim": ssim(r.rgb, r.target),
            "render_seconds": r.seconds,
        }
        if lpips is not None:
            item["lpips"] = lpips.distance(r.rgb.to(device), r.target.to(device))
        per_image.append(item)
        if save_images:
            iio.imwrite(render_dir / f"{unique_safe_name(r.view.name, index, stems)}.png", to_png(r.rgb))
        console.print(  # names come from the dataset: "[x]" is not markup and ":b:" is no emoji
            f"  {escape(r.view.name)}: psnr {item['psnr']:.2f}  ssim {item['ssim']:.4f}"
            + (f"  lpips {item['lpips']:.4f}" if "lpips" in item else ""),
            emoji=False,
        )
    total = time.perf_counter() - started
    if not per_image:
        fail(
            f"the {cfg.split} split of {train_cfg.pipeline.datamanager.dataparser.data} has no views",
            "evaluate another --split",
        )

    results: dict[str, float | None] = {}
    for key in ("psnr", "ssim", "lpips"):
        values = [p[key] for p in per_image if key in p]
        mean, std = mean_and_std(values) if values else (None, None)
        results[key] = mean
        results[f"{key}_std"] = std
    report = {
        "experiment_name": run_dir.parent.parent.name,
        "method_name": train_cfg.method_name,
        "checkpoint": str(ckpt_path),
        "step": step,
        "split": cfg.split,
        "num_views": len(per_image),
        "view_ids": [p["view_id"] for p in per_image],
        "results": results,
        "lpips_backbone": "alex" if lpips is not None else None,
        "timings": {"render_seconds_total": sum(p["render_seconds"] for p in per_image), "eval_seconds": total},
        "per_image": per_image,
        "render_dir": str(render_dir) if save_images else None,
    }
    cfg.output_path.parent.mkdir(parents=True, exist_ok=True)
    cfg.output_path.write_text(json.dumps(report, indent=2) + "\n")
    summary = f"psnr {results['psnr']:.2f}  ssim {results['ssim']:.4f}"
    if results["lpips"] is not None:
        summary += f"  lpips {results['lpips']:.4f}"
    console.print(f"[bold]{train_cfg.method_name} step {step}, {len(per_image)} {cfg.split} views:[/bold] {summary}")
    console.print(f"wrote {cfg.output_path}")
    return report


def main(args: list[str] | None = None) -> dict:
    cfg = tyro.cli(EvalConfig, args=strip_verbose(sys.argv[1:] if args is None else args))
    return evaluate(cfg)


def entrypoint() -> None:
    run_cli(main)


if __name__ == "__main__":
    entrypoint()
