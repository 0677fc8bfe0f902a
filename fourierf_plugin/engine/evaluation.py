"""Scoring a trained run on held-out views: PSNR, SSIM and LPIPS per view and their means, and the renders.

``fourierf-eval`` and ``fourierf-bench`` both call ``evaluate``; it prints nothing itself (``on_view`` hears of
each view as it is scored).
"""

from __future__ import annotations

import shutil
import time
from collections.abc import Callable
from pathlib import Path

import imageio.v3 as iio

from fourierf_plugin.data.dataparser_base import Split
from fourierf_plugin.engine.loading import LoadedRun
from fourierf_plugin.engine.run_dir import unique_safe_name
from fourierf_plugin.utils.colormaps import to_uint8
from fourierf_plugin.utils.errors import fail
from fourierf_plugin.utils.lpips import LPIPS
from fourierf_plugin.utils.metrics import mean_and_std, psnr, ssim

METRICS = ("psnr", "ssim", "lpips")


def evaluate(
    run: LoadedRun,
    split: Split,
    lpips: LPIPS | None = None,
    render_dir: Path | None = None,
    on_view: Callable[[dict], None] | None = None,
) -> dict:
    """Render and score every view of ``split``; the renders go to ``render_dir`` as PNGs (None: not written).

    The PNGs are written into ``<render_dir>.partial`` and the folder is renamed when every view is done, so a
    ``render_dir`` always holds a complete set. Returns the report ``fourierf-eval`` writes: per-image and mean
    metrics, the checkpoint, timings.
    """
    per_image = []
    stems: set[str] = set()  # names from the dataset, made safe and distinct as file names
    started = time.perf_counter()
    partial = None if render_dir is None else render_dir.with_name(render_dir.name + ".partial")
    if partial is not None:
        shutil.rmtree(partial, ignore_errors=True)  # what an interrupted evaluation left
        partial.mkdir(parents=True)
    for index, r in enumerate(run.pipeline.render_views(split, run.step)):
        item = {
            "name": r.view.name,
            "view_id": r.view.view_id,
            "psnr": psnr(r.rgb, r.target),
            "ssim": ssim(r.rgb, r.target),
            "render_seconds": r.seconds,
        }
        if lpips is not None:
            item["lpips"] = lpips.distance(r.rgb.to(run.device), r.target.to(run.device))
        per_image.append(item)
        if partial is not None:
            iio.imwrite(partial / f"{unique_safe_name(r.view.name, index, stems)}.png", to_uint8(r.rgb))
        if on_view is not None:
            on_view(item)
    if not per_image:
        data = run.config.pipeline.datamanager.dataparser.data
        fail(f"the {split} split of {data} has no views", "evaluate another split")
    if render_dir is not None and partial is not None:
        if render_dir.exists():  # an earlier evaluation of the same step and split: the same renders
            shutil.rmtree(render_dir)
        partial.rename(render_dir)
    results: dict[str, float | None] = {}
    for key in METRICS:
        values = [p[key] for p in per_image if key in p]
        mean, std = mean_and_std(values) if values else (None, None)
        results[key] = mean
        results[f"{key}_std"] = std
    return {
        "experiment_name": run.run_dir.parent.parent.name,
        "method_name": run.config.method_name,
        "checkpoint": str(run.checkpoint),
        "step": run.step,
        "split": split,
        "num_views": len(per_image),
        "view_ids": [p["view_id"] for p in per_image],
        "results": results,
        "lpips_backbone": "alex" if lpips is not None else None,
        "timings": {
            "render_seconds_total": sum(p["render_seconds"] for p in per_image),
            "eval_seconds": time.perf_counter() - started,
        },
        "per_image": per_image,
        "render_dir": str(render_dir) if render_dir is not None else None,
    }
