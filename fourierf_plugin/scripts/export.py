"""``fourierf-export marching-cubes --load-config RUN/config.json --output-path mesh.ply``: geometry out of a run.

Subcommands (nerfstudio-style) so that other exporters (point clouds, TSDF) can join without changing the flags of
this one. Meshes are written in the capture's own frame by default (the parser's normalisation undone), so they
overlay the COLMAP model or ``transforms.json`` they came from; an existing file is replaced only with --overwrite.
"""

from __future__ import annotations

import sys
from dataclasses import dataclass
from pathlib import Path
from typing import Literal

import tyro
from rich.markup import escape

from fourierf_plugin.data.dataparser_transforms import RunFrame, read_dataparser_transforms
from fourierf_plugin.exporter.frames import Frame, MeshFrame, resolve_frame
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
from fourierf_plugin.utils.interrupt import note_kept, stop_cleanly


@dataclass
class MarchingCubesConfig(RunOptions):
    """Iso-surface of the density field on a regular grid (scikit-image marching cubes)."""

    output_path: Path = Path("mesh.ply")
    """Mesh file; the format follows the suffix: .ply, .obj or .glb."""
    overwrite: bool = False
    """Replace --output-path when it already exists."""
    frame: Frame = "capture"
    """capture: the world frame of the poses the run was trained on (the COLMAP model, transforms.json or
    poses_bounds.npy), the parser's normalisation undone; normalised: the run's normalised frame; field: the grid's
    own coordinates (NDC for forward-facing runs, contracted coordinates for unbounded ones)."""
    resolution: int = 256
    """Grid vertices per axis (2-1024; memory and time grow with its cube)."""
    bbox_min: tuple[float, float, float] | None = None
    """Lower corner of the sampled box, in the field's coordinates (default: the model's current box; for an
    unbounded run, its part inside the inner cube [-1, 1]³, the object's region)."""
    bbox_max: tuple[float, float, float] | None = None
    """Upper corner of the sampled box, in the field's coordinates (default as --bbox-min)."""
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
    if cfg.output_path.exists() and not cfg.overwrite:
        what = "a folder" if cfg.output_path.is_dir() else "a file"
        fail(
            f"--output-path {cfg.output_path} already exists ({what})",
            "choose another --output-path, or pass --overwrite to replace it",
        )
    if cfg.output_path.is_dir():
        fail(f"--output-path {cfg.output_path} is a folder", "name a mesh file, e.g. mesh.ply")
    check_writable_dir(cfg.output_path.parent, "--output-path")
    check_resolution(cfg.resolution)
    check_frequency_cap(cfg.frequency_cap)
    check_level(cfg.level, cfg.level_kind)
    if cfg.bbox_min is not None and cfg.bbox_max is not None:
        check_bbox(cfg.bbox_min, cfg.bbox_max)
    if cfg.chunk < 1:
        fail(f"--chunk {cfg.chunk} must be at least 1", f"e.g. --chunk {DEFAULT_CHUNK}")


def recorded_frame(run_dir: Path) -> RunFrame | None:
    """The run's ``dataparser_transforms.json`` (None: an older run without one); a broken one is a clear error."""
    try:
        return read_dataparser_transforms(run_dir)
    except ValueError as err:
        fail(str(err), "export with --frame normalised, or restore the file from the run")


def mesh_frame(cfg: MarchingCubesConfig, recorded: RunFrame | None, ray_space: str, far: float) -> MeshFrame:
    """The frame the mesh is written in (``--frame``), from the run's recorded transform."""
    return resolve_frame(cfg.frame, ray_space, recorded, far if ray_space == "contracted" else None)


def default_box(
    aabb: list[list[float]], ray_space: str, object_box: tuple[tuple[float, ...], tuple[float, ...]] | None = None
) -> tuple[tuple[float, ...], tuple[float, ...]]:
    """The model's box; for an unbounded (contracted) run, the object's box where the parser recorded one, else the
    model's box inside the inner cube, where the contraction leaves space as it is (the surroundings are left out)."""
    if ray_space != "contracted":
        return tuple(aabb[0]), tuple(aabb[1])
    low, high = object_box if object_box is not None else ((-1.0,) * 3, (1.0,) * 3)
    return (
        tuple(max(v, b) for v, b in zip(aabb[0], low, strict=True)),
        tuple(min(v, b) for v, b in zip(aabb[1], high, strict=True)),
    )


def run_marching_cubes(cfg: MarchingCubesConfig) -> MeshReport:
    console = get_console()
    check_options(cfg)
    run = cfg.load_run()
    model = run.pipeline.model
    ray_space = model.effects.ray_space
    recorded = recorded_frame(run.run_dir)
    frame = mesh_frame(cfg, recorded, ray_space, float(model.far))
    object_box = None if recorded is None else recorded.object_box
    low, high = default_box(model.aabb.detach().cpu().tolist(), ray_space, object_box)
    bbox = None
    if cfg.bbox_min is not None or cfg.bbox_max is not None or ray_space == "contracted":
        bbox = (cfg.bbox_min or low, cfg.bbox_max or high)
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
        frame=frame,
    )
    note_kept(cfg.output_path)
    for line in describe(report):
        console.print("  " + escape(line), soft_wrap=True)
    return report


def main(args: list[str] | None = None) -> MeshReport:
    cfg = tyro.cli(Commands, args=strip_verbose(sys.argv[1:] if args is None else args))
    if isinstance(cfg, MarchingCubesConfig):
        return run_marching_cubes(cfg)
    raise AssertionError(f"unhandled export command {type(cfg).__name__}")  # pragma: no cover


def entrypoint() -> None:
    run_cli(stop_cleanly(main, "fourierf-export"))


if __name__ == "__main__":
    entrypoint()
