"""``--vis tensorboard``: a run's scalars and, every N steps, renders of one training and one held-out view.

TensorBoard is the log viewer nerfstudio and TensoRF users already have open; the curriculum shows there as the
cutoff curves beside loss and PSNR, and the renders show the scene sharpening as the kept spectrum grows.

Scalars are written at the trainer's log steps (the values metrics.jsonl records); images at every ``image_every``
steps and at the last one, rendered at the step's cutoffs in eval mode. A view larger than ``IMAGE_SIDE`` pixels on its
long side is rendered at a reduced resolution (intrinsics scaled, the target area-downsampled): a log image is for
looking, and a full-size render would cost a CPU run several seconds every time.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Iterator
from pathlib import Path
from typing import TYPE_CHECKING, Any

import torch
import torch.nn.functional as F
from torch import Tensor

from fourierf_plugin.data.datamanager import camera_rays
from fourierf_plugin.engine.observers import StepReport
from fourierf_plugin.model_components.rendering import background_color, composite_target
from fourierf_plugin.utils.colormaps import colorize_depth
from fourierf_plugin.utils.errors import UserError, fail

if TYPE_CHECKING:
    from fourierf_plugin.cameras.cameras import Cameras
    from fourierf_plugin.pipelines.base import Pipeline

IMAGE_SIDE = 256
"""Longest side of a logged render, in pixels."""
SKIPPED_KEYS = frozenset({"step", "phases"})
"""Record entries that are not scalars of their own (the step is the x axis; phases get a group)."""


def summary_writer_class() -> Any:
    """torch's SummaryWriter, or one clear error naming the extra (torch imports it only when tensorboard is there)."""
    try:
        from torch.utils.tensorboard import SummaryWriter
    except ImportError:
        fail("--vis tensorboard needs the tensorboard package", "pip install 'fourierf[tensorboard]'")
    return SummaryWriter


def scalars_of(report: StepReport) -> Iterator[tuple[str, float]]:
    """(tag, value) of every number a logged step records: metrics, cutoffs, lr scale, grid size and phase times."""
    record = report.record or {}
    for key, value in record.items():
        if key in SKIPPED_KEYS or isinstance(value, bool) or not isinstance(value, (int, float)):
            continue
        group = "train" if key in report.metrics else "schedule"
        yield f"{group}/{key}", float(value)
    if report.resolution:
        yield "schedule/grid_voxels", float(math.prod(int(r) for r in report.resolution))
    for name, seconds in (record.get("phases") or {}).items():
        yield f"phases/{name}", float(seconds)


def scaled_cameras(cameras: Cameras, index: int, side: int) -> tuple[Cameras, float]:
    """Camera ``index`` with its image scaled so the long side is at most ``side`` pixels (and the scale used)."""
    one = cameras.subset([index])
    scale = min(1.0, side / max(one.width, one.height))
    if scale == 1.0:
        return one, 1.0
    width, height = max(1, round(one.width * scale)), max(1, round(one.height * scale))
    sx, sy = width / one.width, height / one.height
    scaled = dataclasses.replace(
        one, fx=one.fx * sx, fy=one.fy * sy, cx=one.cx * sx, cy=one.cy * sy, width=width, height=height
    )
    return scaled, scale


class TensorBoardObserver:
    """Writes RUN/tensorboard/ event files (the ``TrainingObserver`` protocol of ``engine.observers``)."""

    def __init__(self, image_every: int, image_side: int = IMAGE_SIDE) -> None:
        self._writer_class = summary_writer_class()  # before the run folder exists: a missing extra stops the run
        self.image_every = int(image_every)
        self.image_side = int(image_side)
        self.writer: Any = None
        self._views: dict[str, tuple[Cameras, Tensor, str]] = {}

    # -- the protocol -------------------------------------------------------------------------------------------
    def started(self, pipeline: Pipeline, run_dir: Path, start_step: int) -> None:
        """Open the writer; a resumed run drops the events logged after its checkpoint (by steps it will redo): those
        from step ``start_step + 1`` on (the checkpoint's own step keeps its record, as metrics.jsonl does)."""
        purge = start_step + 1 if start_step else None
        self.writer = self._writer_class(log_dir=str(Path(run_dir) / "tensorboard"), purge_step=purge)
        self._views = self._pick_views(pipeline)

    def step_done(self, pipeline: Pipeline, report: StepReport) -> None:
        if report.record is not None:
            for tag, value in scalars_of(report):
                self.writer.add_scalar(tag, value, report.step)
        if report.step % self.image_every == 0 or report.step == report.max_steps:
            self._log_images(pipeline, report.step)

    def finished(self, pipeline: Pipeline, step: int, interrupted: bool) -> None:
        if self.writer is not None:
            self.writer.flush()
            self.writer.close()
            self.writer = None

    # -- images -------------------------------------------------------------------------------------------------
    def _pick_views(self, pipeline: Pipeline) -> dict[str, tuple[Cameras, Tensor, str]]:
        """The first training view and the first held-out one (val where the scene has one, else test), read once."""
        views = {}
        parser = pipeline.datamanager.parser
        for label, splits in (("train", ("train",)), ("held_out", ("val", "test"))):
            for split in splits:
                try:
                    outputs = parser.get_outputs(split)  # type: ignore[arg-type]
                except UserError:  # a scene without this split (parsers say so): try the next one
                    continue
                if len(outputs.cameras):
                    views[label] = (outputs.cameras, outputs.images[0], f"{split}:{outputs.image_names[0]}")
                    break
        return views

    @torch.no_grad()
    def _log_images(self, pipeline: Pipeline, step: int) -> None:
        model = pipeline.model
        background = background_color(model.effects.eval_background, 1, pipeline.device, None)
        for label, (cameras, image, name) in self._views.items():
            camera, scale = scaled_cameras(cameras, 0, self.image_side)
            origins, directions = camera_rays(camera, 0, pipeline.datamanager.ray_space)
            out = model.render_rays(origins.to(pipeline.device), directions.to(pipeline.device), step)
            shape = (camera.height, camera.width)
            target = _resized(image, shape) if scale < 1.0 else image
            target_rgb = composite_target(target.reshape(-1, 4).to(pipeline.device), background).view(*shape, 3)
            rgb = out["rgb"].view(*shape, 3).clamp(0.0, 1.0)
            side_by_side = torch.cat([rgb, target_rgb], dim=1).cpu()
            self.writer.add_image(f"{label}/rgb_vs_target", side_by_side, step, dataformats="HWC")
            depth = colorize_depth(out["depth"].view(shape).cpu(), out["accumulation"].view(shape).cpu())
            self.writer.add_image(f"{label}/depth", _as_float_image(depth), step, dataformats="HWC")
            self.writer.add_text(f"{label}/view", name, step)


def _resized(image: Tensor, shape: tuple[int, int]) -> Tensor:
    """[H, W, 4] premultiplied RGBA area-averaged to ``shape`` (exact for premultiplied colour)."""
    chw = image.permute(2, 0, 1).unsqueeze(0)
    return F.interpolate(chw, size=shape, mode="area")[0].permute(1, 2, 0)


def _as_float_image(image: Any) -> Tensor:
    """A colour map's output (uint8 or float, numpy or torch) as float [H, W, 3] in [0, 1]."""
    t = torch.as_tensor(image)
    return t.float() / 255.0 if t.dtype == torch.uint8 else t.float()
