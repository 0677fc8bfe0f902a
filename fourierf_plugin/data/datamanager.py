"""Turns parser outputs into ray batches: every training pixel's ray, shuffled each epoch, and whole eval images."""

from __future__ import annotations

import math
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass, field
from typing import ClassVar

import torch
from torch import Tensor

from fourierf_plugin.cameras.cameras import Cameras
from fourierf_plugin.cameras.ndc import ndc_rays
from fourierf_plugin.cameras.unseen_views import patch_rays, random_corners, random_poses
from fourierf_plugin.configs.base import InstantiateConfig
from fourierf_plugin.data.dataparser_base import DataparserOutputs, Split
from fourierf_plugin.data.parsers import DataParserUnion, default_dataparser
from fourierf_plugin.data.scene_effects import RaySpace
from fourierf_plugin.utils.errors import fail


@dataclass
class RayBatch:
    origins: Tensor  # [R, 3]
    directions: Tensor  # [R, 3] unit
    rgba: Tensor  # [R, 4] premultiplied colour + alpha


@dataclass
class EvalView:
    name: str
    view_id: int
    rays: RayBatch
    height: int
    width: int


def camera_rays(cameras: Cameras, index: int, ray_space: RaySpace) -> tuple[Tensor, Tensor]:
    """Rays of one camera: unit directions in a euclidean scene, NDC origins/directions (not unit) otherwise."""
    if ray_space == "ndc":
        o, d = cameras.generate_rays(index, normalize=False)
        return ndc_rays(o, d, float(cameras.fx[index]), cameras.width, cameras.height, near=1.0)
    return cameras.generate_rays(index)


RaySchedule = tuple[tuple[float, float], ...]
"""Stages of the ray batch: (fraction of the run where the stage starts, multiplier of ``rays_per_batch``)."""

SCHEDULE_FLAG = "--pipeline.datamanager.rays-per-batch-schedule"


def rays_per_batch_at(
    step: int, rays_per_batch: int, schedule: Sequence[Sequence[float]] | None, max_iters: int
) -> int:
    """Training rays at ``step`` of a run of ``max_iters``: ``rays_per_batch`` times the multiplier of the last stage
    of ``schedule`` that has started (a stage at fraction f starts at step ⌊f · max_iters + ½⌋, the rounding of the
    run's other events), ``rays_per_batch`` before the first and without a schedule. A function of the step alone,
    so a resumed run draws the batches the uninterrupted one does."""
    scale = 1.0
    for fraction, multiplier in schedule or ():
        if step >= stage_start(fraction, max_iters):
            scale = multiplier
    return rays_per_batch if scale == 1.0 else max(1, round(rays_per_batch * scale))


def stage_start(fraction: float, max_iters: int) -> int:
    """The step where a ray schedule's stage at ``fraction`` of a run of ``max_iters`` starts."""
    return math.floor(fraction * max_iters + 0.5)


def invalid_schedule(schedule: Sequence[Sequence[float]] | None) -> str | None:
    """Why ``schedule`` cannot be used (what it must be), or None when it can."""
    if schedule is None:
        return None
    fractions = [stage[0] for stage in schedule]
    if any(len(stage) != 2 for stage in schedule):
        return "pairs of (fraction of the run, multiplier)"
    if not all(math.isfinite(f) and 0.0 <= f <= 1.0 for f in fractions) or fractions != sorted(fractions):
        return "stages at increasing fractions of the run in [0, 1]"
    if not all(math.isfinite(m) and m > 0 for _, m in schedule):
        return "multipliers > 0"
    return None


def to_device(tensor: Tensor, device: torch.device) -> Tensor:
    """A host tensor on ``device``; to a GPU through pinned memory, so the copy runs without stalling the host."""
    if device.type == "cuda":
        return tensor.pin_memory().to(device, non_blocking=True)
    return tensor.to(device)


def all_rays(outputs: DataparserOutputs, device: torch.device, ray_space: RaySpace = "euclidean") -> RayBatch:
    """Rays and targets of every pixel of every image of a split, image by image, row-major."""
    rays = [camera_rays(outputs.cameras, i, ray_space) for i in range(len(outputs.cameras))]
    return RayBatch(
        to_device(torch.cat([r[0] for r in rays]), device),
        to_device(torch.cat([r[1] for r in rays]), device),
        to_device(outputs.images.reshape(-1, 4), device),
    )


class DataManager:
    """Owns the training rays (and which of them are still active) and serves eval images on demand."""

    config: DataManagerConfig

    def __init__(
        self,
        config: DataManagerConfig,
        device: torch.device,
        generator: torch.Generator,
        ray_space: RaySpace,
        load_train: bool = True,
        max_iters: int = 1,
    ):
        why = invalid_schedule(config.rays_per_batch_schedule)
        if why is not None:
            shown = " ".join(f"{value:g}" for stage in config.rays_per_batch_schedule or () for value in stage)
            fail(
                f"{SCHEDULE_FLAG} {shown} is out of range: it must be {why}",
                f"pass e.g. {SCHEDULE_FLAG} 0.0051 4 0.0101 16",
            )
        self.config = config
        self.set_run_length(max_iters)  # the run's length, where the ray schedule's fractions fall
        self.device = device
        self.generator = generator  # batches are drawn where it lives (the device, for a GPU step without copies)
        self.parser = config.dataparser.setup()
        self.ray_space = ray_space
        self.train_outputs: DataparserOutputs | None = None
        self._train_rays: RayBatch | None = None
        self.active = torch.zeros(0, dtype=torch.long)
        self._order = torch.zeros(0, dtype=torch.long)
        self._cursor = 0
        self.load_train = load_train
        if load_train:
            self.train_outputs = self.parser.get_outputs("train")
            self.active = torch.arange(self.train_outputs.images[..., 0].numel(), device=generator.device)

    @property
    def train_rays(self) -> RayBatch | None:
        if self._train_rays is None and self.load_train:
            self._train_rays = all_rays(self.reference_outputs, self.device, self.ray_space)
        return self._train_rays

    @property
    def reference_outputs(self) -> DataparserOutputs:
        """The split that defines the scene (box, near/far) for the model."""
        if self.train_outputs is None:
            self.train_outputs = self.parser.get_outputs("train")
        return self.train_outputs

    def keep_rays(self, keep: Callable[[Tensor, Tensor], Tensor]) -> int:
        """Drop training rays for which ``keep(origins, directions)`` is False; returns how many remain."""
        assert self.train_rays is not None
        active = self.active.to(self.device)
        mask = keep(self.train_rays.origins[active], self.train_rays.directions[active]).to(self.active.device)
        if not bool(mask.any()):
            return int(self.active.numel())  # never filter down to nothing; the caller warns
        self.active = self.active[mask]
        self._order = torch.zeros(0, dtype=torch.long)
        self._cursor = 0
        return int(self.active.numel())

    def rays_at(self, step: int) -> int:
        """Training rays at ``step`` (``rays_per_batch``, or its multiple in the schedule's stage at ``step``)."""
        c = self.config
        return rays_per_batch_at(step, c.rays_per_batch, c.rays_per_batch_schedule, self.max_iters)

    def set_run_length(self, max_iters: int) -> None:
        """Place the ray schedule's stages at a run of ``max_iters`` iterations (``set_run_length`` of the model)."""
        self.max_iters = max_iters

    def stage_steps(self) -> list[int]:
        """The steps where the ray schedule's stages start: the run's count-dependent events of the batch."""
        schedule = self.config.rays_per_batch_schedule or ()
        return [stage_start(fraction, self.max_iters) for fraction, _ in schedule]

    def next_batch(self, step: int = 0) -> RayBatch:
        """A batch of training rays for ``step`` (``rays_at``); a fresh permutation each epoch, the tail of an epoch
        dropped."""
        assert self.train_rays is not None
        size = min(self.rays_at(step), int(self.active.numel()))
        if size == 0:
            fail("no training rays left", "check the scene box and near/far planes of the dataset")
        if self._cursor + size > self._order.numel():
            perm = torch.randperm(self.active.numel(), generator=self.generator, device=self.generator.device)
            self._order = self.active[perm]
            self._cursor = 0
        idx = self._order[self._cursor : self._cursor + size].to(self.device)
        self._cursor += size
        r = self.train_rays
        return RayBatch(r.origins[idx], r.directions[idx], r.rgba[idx])

    def unseen_patches(self, count: int, size: int, generator: torch.Generator) -> tuple[Tensor, Tensor]:
        """Origins and directions [count * size², 3] (in the scene's ray space, on the device) of ``count`` random
        ``size × size`` pixel patches seen from random poses between the training cameras (RegNeRF's unseen views),
        drawn from ``generator``."""
        cameras = self.reference_outputs.cameras
        poses = random_poses(cameras.camera_to_worlds.to(generator.device), count, generator)
        corners = random_corners(cameras, count, size, generator)
        o, d = patch_rays(cameras, poses, corners, size, normalize=self.ray_space != "ndc")
        if self.ray_space == "ndc":
            o, d = ndc_rays(o, d, float(cameras.fx[0]), cameras.width, cameras.height, near=1.0)
        return o.to(self.device), d.to(self.device)

    def eval_views(self, split: Split) -> Iterator[EvalView]:
        outputs = self.parser.get_outputs(split)
        for i in range(len(outputs.cameras)):
            o, d = camera_rays(outputs.cameras, i, self.ray_space)
            rgba = outputs.images[i].reshape(-1, 4)
            yield EvalView(
                outputs.image_names[i],
                outputs.view_ids[i],
                RayBatch(to_device(o, self.device), to_device(d, self.device), to_device(rgba, self.device)),
                outputs.cameras.height,
                outputs.cameras.width,
            )

    def state_dict(self) -> dict:
        return {"active": self.active.clone(), "order": self._order.clone(), "cursor": self._cursor}

    def load_state_dict(self, state: dict) -> None:
        self.active = state["active"].long().to(self.generator.device)
        self._order = state["order"].long().to(self.generator.device)
        self._cursor = int(state["cursor"])


@dataclass
class DataManagerConfig(InstantiateConfig):
    _target: ClassVar[type] = DataManager
    dataparser: DataParserUnion = field(default_factory=default_dataparser)
    rays_per_batch: int = 4096
    """Training rays per iteration (the first stage's, with ``rays_per_batch_schedule``)."""
    rays_per_batch_schedule: RaySchedule | None = None
    """Where the batch grows: (fraction of the run, multiplier of ``rays_per_batch``) pairs, each stage from its
    fraction on, 1× before the first (``rays_per_batch_at``); None = ``rays_per_batch`` throughout (zerorf-vm:
    ZeroRF's 1 → 4 → 16 at 0.51% and 1.01% of the run)."""
