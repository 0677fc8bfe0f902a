"""Scoring a trained run on held-out views: PSNR, SSIM and LPIPS per view and their means, and the renders.

``fourierf-eval`` calls ``evaluate``; it prints nothing itself (``on_view`` hears of each view as it is scored).
"""

from __future__ import annotations

import os
import shutil
import tempfile
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
from fourierf_plugin.utils.new_dirs import NewDirs
from fourierf_plugin.utils.os_errors import user_error_for

METRICS = ("psnr", "ssim", "lpips")


def check_render_dir(render_dir: Path, overwrite: bool, keep: tuple[Path, ...] = ()) -> None:
    """Refuse a ``--render-dir`` whose contents the renders would replace: an existing non-empty folder without
    ``overwrite``, and even with it a folder holding anything but PNGs or one that holds ``keep`` (the working
    folder, the run, the report): a mistyped ``..`` must never empty a parent."""
    if not render_dir.exists() and not render_dir.is_symlink():
        return
    if not render_dir.is_dir():
        fail(f"--render-dir {render_dir} is an existing file", "choose a folder path, or 'none' to skip the renders")
    if not any(render_dir.iterdir()):
        return
    if not overwrite:
        fail(
            f"--render-dir {render_dir} already exists and is not empty",
            "choose another --render-dir, or pass --overwrite to replace its renders",
        )
    target = Path(os.path.realpath(render_dir))
    holds = [k for k in keep if target == Path(os.path.realpath(k)) or target in Path(os.path.realpath(k)).parents]
    foreign = [p.name for p in render_dir.iterdir() if p.suffix.lower() != ".png" or not p.is_file()]
    if holds or foreign:
        what = f"holds {holds[0]}" if holds else f"holds more than renders ({', '.join(sorted(foreign)[:3])})"
        fail(f"--render-dir {render_dir} {what}: --overwrite replaces only a folder of renders", "choose a new folder")


def evaluate(
    run: LoadedRun,
    split: Split,
    lpips: LPIPS | None = None,
    render_dir: Path | None = None,
    on_view: Callable[[dict], None] | None = None,
    overwrite: bool = False,
) -> dict:
    """Render and score every view of ``split``; the renders go to ``render_dir`` as PNGs (None: not written).

    The PNGs are written into a hidden sibling folder made for this call and renamed to ``render_dir`` when every
    view is done, so a ``render_dir`` always holds a complete set; an existing non-empty one is replaced only with
    ``overwrite`` (``check_render_dir``), and if the evaluation stops the sibling is removed, with any parent folder
    this call created and left empty. Returns the report ``fourierf-eval`` writes: per-image and mean metrics, the
    checkpoint, timings.
    """
    if render_dir is not None:
        check_render_dir(render_dir, overwrite)
    started = time.perf_counter()
    partial = None
    made = NewDirs()  # the parents of render_dir this call creates: removed again, if left empty, when it stops
    if render_dir is not None:
        made.make(render_dir.parent, "--render-dir")
        try:
            partial = Path(tempfile.mkdtemp(prefix=f".{render_dir.name}.", suffix=".partial", dir=render_dir.parent))
        except OSError as err:
            made.remove_empty()
            fail(f"cannot write to {render_dir.parent} ({err.strerror or err})", "choose a writable --render-dir")
    try:
        per_image = _score_views(run, split, lpips, partial, on_view)
        if render_dir is not None and partial is not None:
            _put_in_place(partial, render_dir, overwrite)
    except BaseException as err:
        if partial is not None:
            shutil.rmtree(partial, ignore_errors=True)  # made by this call: a half-filled folder helps no one
        made.remove_empty()
        problem = user_error_for(err, path=render_dir) if isinstance(err, Exception) else None
        if problem is not None:
            raise problem from err
        raise
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


def _score_views(
    run: LoadedRun,
    split: Split,
    lpips: LPIPS | None,
    folder: Path | None,
    on_view: Callable[[dict], None] | None,
) -> list[dict]:
    """Each view's metrics (its render written to ``folder`` as a PNG); a split without views is a clear error."""
    per_image = []
    stems: set[str] = set()  # names from the dataset, made safe and distinct as file names
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
        if folder is not None:
            iio.imwrite(folder / f"{unique_safe_name(r.view.name, index, stems)}.png", to_uint8(r.rgb))
        if on_view is not None:
            on_view(item)
    if not per_image:
        data = run.config.pipeline.datamanager.dataparser.data
        fail(f"the {split} split of {data} has no views", "evaluate another split")
    return per_image


def _put_in_place(staged: Path, final: Path, overwrite: bool) -> None:
    """Rename the finished folder to ``final``; an earlier non-empty one goes only with ``overwrite``, and only once
    the new set is complete (checked again here: another process may have filled it meanwhile)."""
    check_render_dir(final, overwrite)
    old = None
    if final.exists() and any(final.iterdir()):
        old = final.with_name(f".{final.name}.old-{os.getpid()}")
        final.rename(old)
    elif final.is_dir():
        final.rmdir()  # empty: nothing of the user's is lost
    staged.rename(final)
    if old is not None:
        shutil.rmtree(old, ignore_errors=True)
