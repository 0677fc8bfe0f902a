"""``fourierf-viewer --load-config RUN/config.json``: a saved run in the browser, at any camera and Fourier cutoff.

Runs until Ctrl-C. From Python (tests, benchmarks), ``serve(cfg)`` starts the same page and returns a handle with
the port it took and ``stop()``.
"""

from __future__ import annotations

import sys
import time
from dataclasses import dataclass
from pathlib import Path

import tyro
from rich.markup import escape

from fourierf_plugin.engine.loading import LoadedRun
from fourierf_plugin.scripts.cli import run_cli, strip_verbose
from fourierf_plugin.scripts.run_options import RunOptions
from fourierf_plugin.utils.console import get_console
from fourierf_plugin.utils.errors import fail
from fourierf_plugin.viewer.scene_view import held_out_views
from fourierf_plugin.viewer.server import ViewerServer, ViewerSettings, open_server, require_viser, served_url
from fourierf_plugin.viewer.viewed_run import ViewedRun


@dataclass
class ViewerConfig(RunOptions):
    port: int = 7007
    """Port of the page (the next free one is taken, and said, when it is in use)."""
    host: str = "127.0.0.1"
    """Interface to listen on: 127.0.0.1 is this machine only; 0.0.0.0 (every interface) lets other machines open
    the page, which has no password."""
    preview_side: int = 256
    """Pixels along the longer side of the preview shown while the camera moves."""
    final_side: int | None = None
    """Pixels along the longer side of the picture rendered once the camera rests, drawn coarse to full (default:
    the training images' longer side)."""


@dataclass
class ViewerHandle:
    """A running page: its port, what it shows, and how to stop it."""

    port: int
    run: LoadedRun
    view: ViewerServer
    host: str = "127.0.0.1"

    @property
    def url(self) -> str:
        return served_url(self.host, self.port)

    def stop(self) -> None:
        self.view.stop()


def check_options(cfg: ViewerConfig) -> None:
    """What can be checked before the (slow) load: the extra, the config file, the picture sizes."""
    require_viser()
    if not Path(cfg.load_config).exists():
        fail(
            f"config file not found: {cfg.load_config}",
            "pass the config.json written in a run directory (outputs/<scene>/<method>/<timestamp>/config.json)",
        )
    final = cfg.final_side if cfg.final_side is not None else max(cfg.preview_side, 16)
    if not 16 <= cfg.preview_side <= final:
        fail(
            f"need 16 <= --preview-side <= --final-side, got {cfg.preview_side} and {cfg.final_side}",
            "e.g. --preview-side 256 --final-side 768",
        )


def serve(cfg: ViewerConfig) -> ViewerHandle:
    """Load the run and start its page (returns at once; rendering happens in a background thread)."""
    check_options(cfg)
    run = cfg.load_run()
    server = open_server(cfg.port, cfg.host)
    datamanager = run.pipeline.datamanager
    viewed = ViewedRun(run.pipeline.model, run.step, run.run_dir)
    settings = ViewerSettings(preview_side=cfg.preview_side, final_side=cfg.final_side)
    try:
        view = ViewerServer(server, viewed, datamanager.reference_outputs, held_out_views(datamanager.parser), settings)
    except BaseException:
        server.stop()
        raise
    get_console().print(
        f"[bold]{escape(run.config.method_name)}[/bold] step {run.step} ({escape(str(run.checkpoint))})",
        soft_wrap=True,
    )
    return ViewerHandle(int(server.get_port()), run, view, cfg.host)


def main(args: list[str] | None = None) -> None:
    cfg = tyro.cli(ViewerConfig, args=strip_verbose(sys.argv[1:] if args is None else args))
    handle = serve(cfg)
    try:
        while True:
            time.sleep(1.0)
    except KeyboardInterrupt:
        get_console().print("stopping the viewer")
    finally:
        handle.stop()


def entrypoint() -> None:
    run_cli(main)


if __name__ == "__main__":
    entrypoint()
