"""``fourierf-export marching-cubes --load-config RUN/config.json --output-path mesh.ply``: geometry out of a run.

Subcommands (nerfstudio-style) so that other exporters (point clouds, TSDF) can join without changing the flags of
this one.
"""

from __future__ import annotations

import sys
from dataclasses import dataclass
from pathlib import Path
from typing import Literal

import tyro
from rich.markup import escape

from fourierf_plugin.exporter.marching_cubes import (
    DEFAULT_CHUNK,
    MeshReport,
    check_bbox,
    check_frequency_cap,
    check_level,
    check_resolution,
    check_suffix,
    describe,
    export_field_mesh,
)
from fourierf_plugin.scripts.cli import run_cli, strip_verbose
from fourierf_plugin.scripts.run_options import RunOptions
from fourierf_plugin.utils.console import get_console
from fourierf_plugin.utils.errors import fail
from fourierf_plugin.utils.files import check_writable_dir


@dataclass
class MarchingCubesConfig(RunOptions):
    """Iso-surface of the density field on a regular grid (scikit-image marching cubes)."""

    output_path: Path = Path("mesh.ply")
    """Mesh file; the format follows the suffix: .ply, .obj or .glb."""
    resolution: int = 256
    """Grid vertices per axis (2-1024; memory and time grow with its cube)."""
    bbox_min: tuple[float, float, float] | None = None
    """Lower corner of the sampled box (default: the model's current box)."""
    bbox_max: tuple[float, float, float] | None = None
    """Upper corner of the sampled box (default: the model's current box)."""
    level: Literal["auto"] | float = "auto"
    """Iso-level in --level-kind units; auto = the highest opacity in 0.5 ... 0.01 at which the object is one solid
    piece (the export says which)."""
    level_kind: Literal["opacity", "density"] = "opacity"
    """opacity: alpha 1-exp(-sigma*step*distance_scale) of one ray sample; density: sigma itself."""
    vertex_colors: bool = False
    """Colour the vertices from the appearance field (viewed head-on when colour is view-dependent)."""
    min_component_faces: int | None = None
    """Drop disconnected pieces with fewer faces (floaters); default: 1 % of the largest piece's; 0 keeps all."""
    keep_largest: int | None = None
    """Keep only the k largest pieces."""
    frequency_cap: float | None = None
    """Export the field low-passed at this cutoff in [0, 1] (the coarse geometry); default: the run's own cutoff."""
    chunk: int = DEFAULT_CHUNK
    """Grid points evaluated at once (lower it if the device runs out of memory)."""


Commands = tyro.extras.subcommand_type_from_defaults({"marching-cubes": MarchingCubesConfig(load_config=tyro.MISSING)})


def check_options(cfg: MarchingCubesConfig) -> None:
    """Everything that can be checked without the model, before the (slow) load and sampling."""
    check_suffix(cfg.output_path)
    check_writable_dir(cfg.output_path.parent, "--output-path")
    check_resolution(cfg.resolution)
    check_frequency_cap(cfg.frequency_cap)
    check_level(cfg.level, cfg.level_kind)
    if cfg.bbox_min is not None and cfg.bbox_max is not None:
        check_bbox(cfg.bbox_min, cfg.bbox_max)
    if cfg.chunk < 1:
        fail(f"--chunk {cfg.chunk} must be at least 1", f"e.g. --chunk {DEFAULT_CHUNK}")


def run_marching_cubes(cfg: MarchingCubesConfig) -> MeshReport:
    console = get_console()
    check_options(cfg)
    run = cfg.load_run()
    model = run.pipeline.model
    bbox = None
    if cfg.bbox_min is not None or cfg.bbox_max is not None:
        aabb = model.aabb.detach().cpu().tolist()
        bbox = (cfg.bbox_min or tuple(aabb[0]), cfg.bbox_max or tuple(aabb[1]))
    console.print(
        f"[bold]{run.config.method_name}[/bold] step {run.step} ({escape(str(run.checkpoint))}): "
        f"marching cubes at {cfg.resolution}³ on {run.device}",
        soft_wrap=True,
    )
    report = export_field_mesh(
        model,
        run.step,
        cfg.output_path,
        resolution=cfg.resolution,
        bbox=bbox,
        level=cfg.level,
        level_kind=cfg.level_kind,
        colors=cfg.vertex_colors,
        frequency_cap=cfg.frequency_cap,
        min_component_faces=cfg.min_component_faces,
        keep_largest=cfg.keep_largest,
        chunk=cfg.chunk,
    )
    for line in describe(report):
        console.print("  " + escape(line), soft_wrap=True)
    return report


def main(args: list[str] | None = None) -> MeshReport:
    cfg = tyro.cli(Commands, args=strip_verbose(sys.argv[1:] if args is None else args))
    if isinstance(cfg, MarchingCubesConfig):
        return run_marching_cubes(cfg)
    raise AssertionError(f"unhandled export command {type(cfg).__name__}")  # pragma: no cover


def entrypoint() -> None:
    run_cli(main)


if __name__ == "__main__":
    entrypoint()
