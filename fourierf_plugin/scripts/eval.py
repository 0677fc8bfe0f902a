"""``fourierf-eval --load-config RUN/config.json --output-path eval.json``: metrics on held-out views."""

from __future__ import annotations

import sys
from dataclasses import dataclass
from pathlib import Path
from typing import Literal

import tyro
from rich.markup import escape

from fourierf_plugin.engine.evaluation import evaluate
from fourierf_plugin.scripts.cli import run_cli, strip_verbose
from fourierf_plugin.scripts.run_options import RunOptions
from fourierf_plugin.utils.console import get_console, warn, write_json
from fourierf_plugin.utils.files import check_writable_dir
from fourierf_plugin.utils.lpips import LPIPS, default_lpips_weights


@dataclass
class EvalConfig(RunOptions):
    output_path: Path = Path("eval.json")
    """Where to write the metrics JSON."""
    split: Literal["test", "val", "train"] = "test"
    """Which views to evaluate (tune on val, report on test)."""
    lpips_weights: Path | None = None
    """LPIPS-alex v0.1 weights (default: $FOURIERF_LPIPS_WEIGHTS or ../shared/lpips)."""
    render_dir: Path | None = None
    """Where to save the rendered images (default: RUN/renders/<split>-step<N>/; 'none' skips)."""


def print_view(item: dict) -> None:
    get_console().print(  # names come from the dataset: "[x]" is not markup and ":b:" is no emoji
        f"  {escape(item['name'])}: psnr {item['psnr']:.2f}  ssim {item['ssim']:.4f}"
        + (f"  lpips {item['lpips']:.4f}" if "lpips" in item else ""),
        emoji=False,
    )


def run_eval(cfg: EvalConfig) -> dict:
    console = get_console()
    check_writable_dir(cfg.output_path.parent, "--output-path")
    if cfg.render_dir is not None and str(cfg.render_dir).lower() != "none":
        check_writable_dir(cfg.render_dir.parent, "--render-dir")
    run = cfg.load_run()
    weights = cfg.lpips_weights or default_lpips_weights()
    lpips = LPIPS(weights).to(run.device) if weights is not None else None
    if lpips is None:
        warn("LPIPS weights not found; LPIPS is skipped (pass --lpips-weights PATH to include it)")
    render_dir = cfg.render_dir or run.run_dir / "renders" / f"{cfg.split}-step{run.step:06d}"
    report = evaluate(run, cfg.split, lpips, None if str(render_dir).lower() == "none" else render_dir, print_view)
    write_json(cfg.output_path, report)
    results = report["results"]
    summary = f"psnr {results['psnr']:.2f}  ssim {results['ssim']:.4f}"
    if results["lpips"] is not None:
        summary += f"  lpips {results['lpips']:.4f}"
    views = f"{report['num_views']} {cfg.split} views"
    console.print(f"[bold]{run.config.method_name} step {run.step}, {views}:[/bold] {summary}")
    console.print(f"wrote {cfg.output_path}")
    return report


def main(args: list[str] | None = None) -> dict:
    cfg = tyro.cli(EvalConfig, args=strip_verbose(sys.argv[1:] if args is None else args))
    return run_eval(cfg)


def entrypoint() -> None:
    run_cli(main)


if __name__ == "__main__":
    entrypoint()
