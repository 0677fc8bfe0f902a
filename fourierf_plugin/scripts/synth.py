"""``fourierf-synth --output-dir DIR``: a Blender-format dataset of an analytic scene, with its true geometry.

Why: a scene whose surface is known exactly lets the exported mesh be scored (Chamfer distance against
``DIR/geometry.json``) and gives tests and demos a dataset that needs no download.
"""

from __future__ import annotations

import sys
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Literal

import tyro

from fourierf_plugin.scripts.cli import run_cli, strip_verbose
from fourierf_plugin.synthetic import default_scene, load_scene, write_blender_dataset
from fourierf_plugin.utils.console import get_console
from fourierf_plugin.utils.errors import fail
from fourierf_plugin.utils.files import check_writable_dir


@dataclass
class SynthConfig:
    output_dir: Path
    """Folder for transforms_{train,val,test}.json, the PNGs and geometry.json."""
    width: int = 100
    """Image width in pixels (at least 8)."""
    height: int = 100
    """Image height in pixels (at least 8)."""
    n_train: int = 4
    """Training views (a golden-angle spiral over the upper hemisphere)."""
    n_val: int = 4
    """Validation views (their own spiral, turned away from the training one)."""
    n_test: int = 8
    """Test views (their own spiral, turned away from the training one)."""
    seed: int = 0
    """Seed of the spirals' turns: the same seed gives the same cameras."""
    shading: Literal["none", "lambert"] = "none"
    """none: the albedo only (exact colours); lambert: a directional light plus ambient."""
    samples_per_pixel: int = 1
    """k: a k x k grid of rays per pixel, for antialiased edges (1 gives hard 0/1 alpha)."""
    camera_angle_x: float = 0.69
    """Horizontal field of view in radians (NeRF-synthetic uses 0.69)."""
    radius: float = 4.0
    """Distance of the cameras from the origin (the Blender parser's near/far are 2 and 6)."""
    ground_plane: bool = False
    """Add a grey ground square under the default scene."""
    scene: Path | None = None
    """Render this geometry.json instead of the default scene (spheres, boxes, ground plane)."""
    overwrite: bool = False
    """Allow writing into a non-empty output folder (files of the same names are replaced)."""


def _check_output_dir(cfg: SynthConfig) -> None:
    out = cfg.output_dir
    if out.exists() and not out.is_dir():
        fail(f"--output-dir {out} is a file", "pass a folder path (it is created if missing)")
    if out.is_dir() and any(out.iterdir()) and not cfg.overwrite:
        fail(f"--output-dir {out} already exists and is not empty", "pass --overwrite, or choose a new folder")
    check_writable_dir(out.parent, "--output-dir")


def synthesize(cfg: SynthConfig) -> Path:
    _check_output_dir(cfg)
    if cfg.scene is not None and cfg.ground_plane:
        fail("--ground-plane only applies to the default scene, not to --scene", "add the plane to the JSON instead")
    spec = load_scene(cfg.scene) if cfg.scene is not None else default_scene(ground_plane=cfg.ground_plane)
    started = time.perf_counter()
    out = write_blender_dataset(
        spec,
        cfg.output_dir,
        width=cfg.width,
        height=cfg.height,
        n_train=cfg.n_train,
        n_val=cfg.n_val,
        n_test=cfg.n_test,
        seed=cfg.seed,
        camera_angle_x=cfg.camera_angle_x,
        radius=cfg.radius,
        shading=cfg.shading,
        samples_per_pixel=cfg.samples_per_pixel,
    )
    console = get_console()
    which = str(cfg.scene) if cfg.scene is not None else "the default scene"
    console.print(
        f"wrote {which} ({len(spec.primitives)} primitives) to {out}: {cfg.n_train} train, {cfg.n_val} val, "
        f"{cfg.n_test} test views at {cfg.width}x{cfg.height} in {time.perf_counter() - started:.1f}s",
        soft_wrap=True,
    )
    console.print(f"true geometry: {out / 'geometry.json'}", soft_wrap=True)
    console.print(f"train on it: fourierf-train fourierf-vm --data {out}", soft_wrap=True)
    return out


def main(args: list[str] | None = None) -> Path:
    cfg = tyro.cli(SynthConfig, args=strip_verbose(sys.argv[1:] if args is None else args))
    return synthesize(cfg)


def entrypoint() -> None:
    run_cli(main)


if __name__ == "__main__":
    entrypoint()
