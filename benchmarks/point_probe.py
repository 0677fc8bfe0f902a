"""Which views of a run see a 3-D point, and at what depth each renders the ray that passes through it.

Why: a near blob in a depth map is either a floater (density where the training views have no surface: their rays
through the point render deeper than it) or a real near object the field renders too wide (the views that see it
render their rays through the point at the point's depth). The picture grids (``picture_grid.py``) show the blob;
this says which of the two it is.

    python benchmarks/point_probe.py --run RUN/config.json --point -0.48 -0.80 -0.34

The point is in the model's coordinates (NDC on forward-facing scenes, where the depth is the NDC ray parameter).
For each view: the pixel whose ray passes closest to the point, how far it misses, the point's depth along that ray
and the depth the run renders there.
"""

from __future__ import annotations

import argparse
from dataclasses import dataclass
from pathlib import Path

import torch

from fourierf_plugin.engine.loading import load_run
from fourierf_plugin.method_configs import config_registry
from fourierf_plugin.pipelines.base import Pipeline
from fourierf_plugin.scripts.cli import run_cli


@dataclass(frozen=True)
class Sighting:
    view: str
    row: int
    col: int
    miss: float
    """Distance from the point to the closest ray (in model units)."""
    point_depth: float
    """Where the point lies along that ray."""
    rendered_depth: float
    """The depth the run renders for that ray: equal to ``point_depth`` where the point is the visible surface."""


def closest_pixel(origins: torch.Tensor, directions: torch.Tensor, point: torch.Tensor) -> tuple[int, float, float]:
    """Index of the ray passing closest to ``point``, that distance, and the point's ray parameter along it."""
    t = ((point - origins) * directions).sum(-1) / (directions * directions).sum(-1)
    miss = (origins + t[:, None] * directions - point).norm(dim=-1)
    index = int(torch.argmin(miss))
    return index, float(miss[index]), float(t[index])


def probe(pipeline: Pipeline, step: int, point: torch.Tensor, split: str = "train") -> list[Sighting]:
    """One sighting per view of ``split``, in the split's order."""
    sightings = []
    for view in pipeline.datamanager.eval_views(split):  # type: ignore[arg-type]
        origins, directions = view.rays.origins, view.rays.directions
        index, miss, point_depth = closest_pixel(origins, directions, point.to(origins))
        rendered = pipeline.model.render_rays(origins[index : index + 1], directions[index : index + 1], step)
        row, col = divmod(index, view.width)
        sightings.append(Sighting(view.name, row, col, miss, point_depth, float(rendered["depth"][0])))
    return sightings


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--run", type=Path, required=True, help="config.json of the run")
    ap.add_argument("--point", type=float, nargs=3, required=True, metavar=("X", "Y", "Z"))
    ap.add_argument("--split", default="train", choices=("train", "val", "test"))
    args = ap.parse_args(argv)
    run = load_run(args.run, config_registry(), device="cpu")
    print("| view | pixel (row, col) | miss | point depth | rendered depth |\n|---|---|---|---|---|")
    for s in probe(run.pipeline, run.step, torch.tensor(args.point), args.split):
        print(f"| {s.view} | {s.row}, {s.col} | {s.miss:.3f} | {s.point_depth:.3f} | {s.rendered_depth:.3f} |")


if __name__ == "__main__":
    run_cli(main)  # a missing or broken run: one message and its fix, exit 2
