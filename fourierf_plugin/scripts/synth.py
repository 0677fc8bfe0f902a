"""``fourierf-synth --output-dir DIR``: a dataset of an analytic scene, with its true geometry.

Why: a scene whose surface is known exactly lets the exported mesh be scored (Chamfer distance against
``DIR/geometry.json``) and gives tests and demos a dataset that needs no download. ``--kind objects`` (the default)
writes shapes on a transparent background in the Blender format; ``--kind room`` writes a phone-like capture of a
textured object in a textured room over a partial arc, in the nerfstudio format, with depth and the object's surface.
"""

from __future__ import annotations

import math
import sys
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Literal, TypeVar

import tyro

from fourierf_plugin.scripts.cli import run_cli, strip_verbose
from fourierf_plugin.synthetic import default_scene, load_scene, write_blender_dataset
from fourierf_plugin.synthetic import room as room_capture
from fourierf_plugin.utils.console import get_console
from fourierf_plugin.utils.errors import fail
from fourierf_plugin.utils.files import check_writable_dir

T = TypeVar("T")


@dataclass
class SynthConfig:
    output_dir: Path
    """Folder for the dataset (objects: transforms_{train,val,test}.json, PNGs, geometry.json; room: see --kind)."""
    kind: Literal["objects", "room"] = "objects"
    """objects: spheres and boxes on a transparent background, cameras all around (Blender format). room: a textured
    object on a table in a textured room, RGB photos over a partial arc at the object's height, as a nerfstudio capture
    (transforms.json, images/, points.ply, depth/ of the test views, geometry.json, object.json, object_surface.ply)."""
    width: int | None = None
    """Image width in pixels (at least 8); default 100 (objects) or 160 (room)."""
    height: int | None = None
    """Image height in pixels (at least 8); default 100 (objects) or 120 (room)."""
    n_train: int | None = None
    """Training views; default 4 (objects: a golden-angle spiral over the upper hemisphere) or 30 (room: candidates
    evenly spaced along the arc, ends included, for --num-views to pick from)."""
    n_val: int | None = None
    """Validation views (objects only, default 4: their own spiral, turned away from the training one)."""
    n_test: int | None = None
    """Test views; default 8 (objects: their own turned spiral; room: each halfway between two training views)."""
    seed: int = 0
    """Seed of the spirals' turns (objects) or of the hand-held jitter and the sparse points (room)."""
    shading: Literal["none", "lambert"] | None = None
    """none: the albedo only (exact colours); lambert: a directional light plus ambient. Default: none (objects),
    lambert (room)."""
    samples_per_pixel: int | None = None
    """k: a k x k grid of rays per pixel, for antialiased edges; default 1 (objects: hard 0/1 alpha) or 3 (room)."""
    camera_angle_x: float | None = None
    """Horizontal field of view in radians; default 0.69 (NeRF-synthetic) or 1.134 (room: a phone's 65°)."""
    radius: float | None = None
    """Distance of the cameras from the origin, default 4 (objects: the Blender parser's near/far are 2 and 6); room:
    horizontal distance from the object, default 1."""
    arc_deg: float | None = None
    """Room only: the arc of azimuth the cameras span about the object, in degrees (default 110)."""
    ground_plane: bool = False
    """Objects only: add a grey ground square under the default scene."""
    scene: Path | None = None
    """Objects only: render this geometry.json instead of the default scene (spheres, boxes, ground plane)."""
    overwrite: bool = False
    """Allow writing into a non-empty output folder (files of the same names are replaced)."""


def _check_output_dir(cfg: SynthConfig) -> None:
    out = cfg.output_dir
    if out.exists() and not out.is_dir():
        fail(f"--output-dir {out} is a file", "pass a folder path (it is created if missing)")
    if out.is_dir() and any(out.iterdir()) and not cfg.overwrite:
        fail(f"--output-dir {out} already exists and is not empty", "pass --overwrite, or choose a new folder")
    check_writable_dir(out.parent, "--output-dir")


def _or(value: T | None, default: T) -> T:
    return default if value is None else value


def synthesize(cfg: SynthConfig) -> Path:
    if cfg.kind == "room":
        return _synthesize_room(cfg)
    if cfg.arc_deg is not None:
        fail("--arc-deg only applies to --kind room", "drop --arc-deg, or pass --kind room")
    _check_output_dir(cfg)
    if cfg.scene is not None and cfg.ground_plane:
        fail("--ground-plane only applies to the default scene, not to --scene", "add the plane to the JSON instead")
    spec = load_scene(cfg.scene) if cfg.scene is not None else default_scene(ground_plane=cfg.ground_plane)
    started = time.perf_counter()
    width, height = _or(cfg.width, 100), _or(cfg.height, 100)
    n_train, n_val, n_test = _or(cfg.n_train, 4), _or(cfg.n_val, 4), _or(cfg.n_test, 8)
    out = write_blender_dataset(
        spec,
        cfg.output_dir,
        width=width,
        height=height,
        n_train=n_train,
        n_val=n_val,
        n_test=n_test,
        seed=cfg.seed,
        camera_angle_x=_or(cfg.camera_angle_x, 0.69),
        radius=_or(cfg.radius, 4.0),
        shading=_or(cfg.shading, "none"),
        samples_per_pixel=_or(cfg.samples_per_pixel, 1),
    )
    console = get_console()
    which = str(cfg.scene) if cfg.scene is not None else "the default scene"
    console.print(
        f"wrote {which} ({len(spec.primitives)} primitives) to {out}: {n_train} train, {n_val} val, "
        f"{n_test} test views at {width}x{height} in {time.perf_counter() - started:.1f}s",
        soft_wrap=True,
    )
    console.print(f"true geometry: {out / 'geometry.json'}", soft_wrap=True)
    console.print(f"train on it: fourierf-train fourierf-vm --data {out}", soft_wrap=True)
    return out


def _synthesize_room(cfg: SynthConfig) -> Path:
    for flag, given in (("--n-val", cfg.n_val is not None), ("--ground-plane", cfg.ground_plane)):
        if given:
            fail(
                f"{flag} does not apply to --kind room",
                "drop it (the room's validation views are the training candidates a run does not train on)"
                if flag == "--n-val"
                else "drop it (the room has its own floor)",
            )
    if cfg.scene is not None:
        fail("--scene does not apply to --kind room", "drop --scene, or drop --kind room to render the JSON")
    _check_output_dir(cfg)
    started = time.perf_counter()
    width, height = _or(cfg.width, 160), _or(cfg.height, 120)
    n_train, n_test = _or(cfg.n_train, 30), _or(cfg.n_test, 8)
    arc = _or(cfg.arc_deg, room_capture.DEFAULT_ARC_DEG)
    out = room_capture.write_room_capture(
        cfg.output_dir,
        width=width,
        height=height,
        n_train=n_train,
        n_test=n_test,
        seed=cfg.seed,
        camera_angle_x=_or(cfg.camera_angle_x, math.radians(room_capture.DEFAULT_FOV_DEG)),
        radius=_or(cfg.radius, room_capture.DEFAULT_RADIUS),
        arc_deg=arc,
        shading=_or(cfg.shading, "lambert"),
        samples_per_pixel=_or(cfg.samples_per_pixel, 3),
    )
    console = get_console()
    console.print(
        f"wrote the room capture to {out}: {n_train} train candidates and {n_test} test views on a {arc:g}° arc at "
        f"{width}x{height} in {time.perf_counter() - started:.1f}s",
        soft_wrap=True,
    )
    console.print(
        f"true geometry: {out / 'geometry.json'} (the object alone: {out / room_capture.OBJECT_FILE}, "
        f"{out / room_capture.OBJECT_SURFACE_FILE}); test-view depth: {out / room_capture.DEPTH_DIR}",
        soft_wrap=True,
    )
    console.print(f"train on it: fourierf-train fourierf-vm --data {out} nerfstudio-data --num-views 8", soft_wrap=True)
    return out


def main(args: list[str] | None = None) -> Path:
    cfg = tyro.cli(SynthConfig, args=strip_verbose(sys.argv[1:] if args is None else args))
    return synthesize(cfg)


def entrypoint() -> None:
    run_cli(main)


if __name__ == "__main__":
    entrypoint()
