"""``fourierf-eval --load-config RUN/config.json --output-path eval.json``: metrics on held-out views."""

from __future__ import annotations

import sys
from dataclasses import dataclass
from pathlib import Path
from typing import Literal

import tyro
from rich.markup import escape

from fourierf_plugin.engine.evaluation import check_render_dir, evaluate
from fourierf_plugin.engine.run_dir import lock_output
from fourierf_plugin.scripts.cli import run_cli, strip_verbose
from fourierf_plugin.scripts.run_options import RunOptions
from fourierf_plugin.utils.console import get_console, warn, write_json
from fourierf_plugin.utils.errors import fail
from fourierf_plugin.utils.files import check_writable_dir, run_renders_dir
from fourierf_plugin.utils.interrupt import note_kept, stop_cleanly
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
    """Where to save the rendered images (default: RUN/renders/<split>-step<N>/, or a free -1, -2 ... beside an
    earlier one; 'none' skips)."""
    overwrite: bool = False
    """Replace an existing --output-path and a --render-dir of earlier renders (otherwise both are refused)."""


def print_view(item: dict) -> None:
    get_console().print(  # names come from the dataset: "[x]" is not markup and ":b:" is no emoji
        f"  {escape(item['name'])}: psnr {item['psnr']:.2f}  ssim {item['ssim']:.4f}"
        + (f"  lpips {item['lpips']:.4f}" if "lpips" in item else ""),
        emoji=False,
    )


def skips_renders(path: Path | None) -> bool:
    return path is not None and str(path).lower() == "none"


def check_outputs(cfg: EvalConfig) -> None:
    """Before any work: the report and the renders can be written, and replace nothing without --overwrite."""
    out = cfg.output_path
    if out.is_dir():
        fail(f"--output-path {out} is a folder", "name the report file, e.g. --output-path eval.json")
    if out.exists() and not cfg.overwrite:
        fail(f"--output-path {out} already exists", "choose another --output-path, or pass --overwrite to replace it")
    check_writable_dir(out.parent, "--output-path")
    if cfg.render_dir is not None and not skips_renders(cfg.render_dir):
        check_render_dir(cfg.render_dir, cfg.overwrite, keep=(Path.cwd(), out, Path(cfg.load_config)))
        check_writable_dir(cfg.render_dir.parent, "--render-dir")


def run_eval(cfg: EvalConfig) -> dict:
    console = get_console()
    check_outputs(cfg)
    locks = [lock_output(cfg.output_path, "--output-path")]  # a second evaluation into the same report stops here
    claimed = None
    try:
        run = cfg.load_run()
        weights = cfg.lpips_weights or default_lpips_weights()
        lpips = LPIPS(weights).to(run.device) if weights is not None else None
        if lpips is None:
            warn("LPIPS weights not found; LPIPS is skipped (pass --lpips-weights PATH to include it)")
        render_dir = cfg.render_dir
        if render_dir is None:  # created now, so an evaluation started beside this one takes the next free folder
            render_dir = run_renders_dir(run.run_dir, cfg.split, run.step, cfg.overwrite, claim=not cfg.overwrite)
            claimed = None if cfg.overwrite else render_dir
        renders = None if skips_renders(render_dir) else render_dir
        if renders is not None:
            renders.parent.mkdir(parents=True, exist_ok=True)  # RUN/renders/ on a first --overwrite evaluation
            locks.append(lock_output(renders, "--render-dir"))
        report = evaluate(run, cfg.split, lpips, renders, print_view, cfg.overwrite)
        if renders is not None:
            note_kept(renders)
        write_json(cfg.output_path, report)
        note_kept(cfg.output_path)
    finally:
        if claimed is not None and claimed.is_dir() and not any(claimed.iterdir()):
            claimed.rmdir()  # claimed by this call and never filled
        for lock in locks:
            lock.release()
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
    run_cli(stop_cleanly(main, "fourierf-eval"))


if __name__ == "__main__":
    entrypoint()
