"""A picture grid of held-out views (ground truth | each run; RGB, depth, accumulation): what a PSNR does not show.

    python benchmarks/picture_grid.py --runs A/config.json B/config.json --labels fourierf-vm tensorf-vm \
        --output docs/fern_grid.png
"""

from __future__ import annotations

import argparse
from collections.abc import Sequence
from pathlib import Path

import imageio.v3 as iio
import numpy as np
from skimage.transform import resize

from fourierf_plugin.accel.allocator import keep_freed_memory
from fourierf_plugin.engine.loading import load_run
from fourierf_plugin.method_configs import config_registry
from fourierf_plugin.utils.colormaps import colorize_accumulation, colorize_depth, depth_range, to_uint8


def columns(config: Path, split: str, views: int, names: Sequence[str] = ()) -> list[dict]:
    """The split's views ``names`` (else its first ``views``) rendered, the names checked before a view renders."""
    run = load_run(config, config_registry(), device="cpu")
    split_names = [view.name for view in run.pipeline.datamanager.eval_views(split)]
    if missing := [name for name in names if name not in split_names]:
        raise SystemExit(f"error: {config}: no view {', '.join(missing)} in its {split} split (it has {split_names})")
    wanted = list(names) or split_names[:views]
    return [
        {"name": r.view.name, "rgb": r.rgb, "target": r.target, "depth": r.depth, "acc": r.accumulation}
        for r in run.pipeline.render_views(split, run.step, wanted)
    ]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--runs", type=Path, nargs="+", required=True, help="config.json of each run (one column each)")
    ap.add_argument("--labels", nargs="+", required=True)
    ap.add_argument("--split", default="test")
    ap.add_argument("--views", type=int, default=2, help="how many of the split's views (rows of RGB/depth/acc)")
    ap.add_argument("--view-names", nargs="+", default=(), help="these views of the split instead (e.g. r_0 r_80)")
    ap.add_argument("--output", type=Path, required=True)
    ap.add_argument("--downscale", type=int, default=2, help="shrink the grid by this factor (a smaller docs/ file)")
    args = ap.parse_args()
    keep_freed_memory()  # as the console scripts do: renders reuse freed tensor memory instead of faulting it back
    if len(args.labels) != len(args.runs):
        raise SystemExit("error: give one --labels entry per --runs entry")
    renders = [columns(config, args.split, args.views, args.view_names) for config in args.runs]
    rows = []
    for k in range(len(renders[0])):
        rgb = [to_uint8(renders[0][k]["target"]), *[to_uint8(col[k]["rgb"]) for col in renders]]
        blank = np.full_like(rgb[0], 255)
        low, high = depth_range(renders[0][k]["depth"].numpy(), renders[0][k]["acc"].numpy())  # first run's range
        depth = [colorize_depth(col[k]["depth"], col[k]["acc"], low, high) for col in renders]
        acc = [colorize_accumulation(col[k]["acc"]) for col in renders]
        rows += [np.concatenate(rgb, axis=1), np.concatenate([blank, *depth], axis=1), np.concatenate([blank, *acc], 1)]
    names = [view["name"] for view in renders[0]]
    args.output.parent.mkdir(parents=True, exist_ok=True)
    grid = np.concatenate(rows, axis=0)
    if args.downscale > 1:
        shape = (grid.shape[0] // args.downscale, grid.shape[1] // args.downscale, 3)
        grid = (resize(grid, shape, anti_aliasing=True) * 255).round().astype(np.uint8)
    iio.imwrite(args.output, grid)
    heads = " | ".join(["ground truth", *args.labels])
    print(f"wrote {args.output}: views {names}; columns {heads}; rows rgb, depth, accumulation")


if __name__ == "__main__":
    main()
