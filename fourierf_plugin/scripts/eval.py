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
from fourierf_plugin.utils.new_dirs import NewDirs


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


def check_outputs(cfg: EvalConfig, made: NewDirs) -> None:
    """Before any work: the report and the renders can be written, and replace nothing without --overwrite; the
    folders created for them are recorded in ``made``."""
    out = cfg.output_path
    if out.is_dir():
        fail(f"--output-path {out} is a folder", "name the report file, e.g. --output-path eval.json")
    if out.exists() and not cfg.overwrite:
        fail(f"--output-path {out} already exists", "choose another --output-path, or pass --overwrite to replace it")
    renders = cfg.render_dir if cfg.render_dir is not None and not skips_renders(cfg.render_dir) else None
    if renders is not None:
        check_render_dir(renders, cfg.overwrite, keep=(Path.cwd(), out, Path(cfg.load_config)))
    check_writable_dir(made.make(out.parent, "--output-path"), "--output-path")
    if renders is not None:
        check_writable_dir(made.make(renders.parent, "--render-dir"), "--render-dir")


def run_eval(cfg: EvalConfig) -> dict:
    console = get_console()
    with NewDirs() as made:  # a stopped evaluation removes the folders it made and left empty, and only those
        check_outputs(cfg, made)
        locks = [lock_output(cfg.output_path, "--output-path")]  # a second evaluation into one report stops here
        try:
            run = cfg.load_run()
            weights = cfg.lpips_weights or default_lpips_weights()
            lpips = LPIPS(weights).to(run.device) if weights is not None else None
            if lpips is None:
                warn("LPIPS weights not found; LPIPS is skipped (pass --lpips-weights PATH to include it)")
            render_dir = cfg.render_dir
            if render_dir is None:  # created now, so an evaluation started beside this one takes the next free folder
                made.make(run.run_dir / "renders", "--render-dir")
                render_dir = run_renders_dir(run.run_dir, cfg.split, run.step, cfg.overwrite, claim=not cfg.overwrite)
                if not cfg.overwrite:
                    made.adopt(render_dir)
            renders = None if skips_renders(render_dir) else render_dir
            if renders is not None:
                locks.append(lock_output(renders, "--render-dir"))
            report = evaluate(run, cfg.split, lpips, renders, print_view, cfg.overwrite)
            if renders is not None:
                note_kept(renders)
            write_json(cfg.output_path, report)
            note_kept(cfg.output_path)
        finally:
            for lock in locks:  # before the folders go: a lock file lives beside its output
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
