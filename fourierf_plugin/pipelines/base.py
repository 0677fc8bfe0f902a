"""The pipeline ties the datamanager to the model: one training step, the structural updates, and evaluation."""

from __future__ import annotations

import time
from collections.abc import Collection, Iterator
from dataclasses import dataclass, field
from typing import ClassVar

import torch
from torch import Tensor

from fourierf_plugin.accel.config import uses_gpu_paths
from fourierf_plugin.configs.base import InstantiateConfig
from fourierf_plugin.data.datamanager import DataManager, DataManagerConfig, EvalView
from fourierf_plugin.data.dataparser_base import Split
from fourierf_plugin.data.scene_effects import EffectsConfig
from fourierf_plugin.model_components.rendering import background_color, composite_target
from fourierf_plugin.models.fourierf import Changes, FourieRFModel, FourieRFModelConfig
from fourierf_plugin.pipelines.ray_chunks import accumulate_in_chunks, chunk_spans, max_training_samples
from fourierf_plugin.utils.console import get_console
from fourierf_plugin.utils.errors import fail
from fourierf_plugin.utils.phases import phase


@dataclass
class RenderedView:
    view: EvalView
    rgb: Tensor  # [H, W, 3]
    target: Tensor  # [H, W, 3] on the eval background
    depth: Tensor  # [H, W]
    accumulation: Tensor  # [H, W]
    seconds: float


class Pipeline:
    config: PipelineConfig

    def __init__(
        self,
        config: PipelineConfig,
        device: torch.device,
        max_iters: int,
        generator: torch.Generator,
        load_train: bool = True,
    ) -> None:
        self.config = config
        self.device = device
        self.effects = config.effects.effects()
        self.step_generator = step_generator(generator, device, uses_gpu_paths(config.model.accel, device))
        self.datamanager: DataManager = config.datamanager.setup(
            device=device,
            generator=self.step_generator,
            ray_space=self.effects.ray_space,
            load_train=load_train,
            max_iters=max_iters,
        )
        scene = self.datamanager.reference_outputs
        check_patch_fits(config.model, scene.cameras.width, scene.cameras.height)
        if config.model.depth_smoothness_weight > 0 and self.effects.background != "none":
            get_console().print(
                "[yellow]warning:[/yellow] depth smoothness on a scene with a background: rays that miss the object "
                "read as the far plane, so the term tears the object's silhouettes and costs quality; it is meant for "
                "forward-facing photos"
            )
        self.model: FourieRFModel = config.model.setup(
            scene_box=scene.scene_box.to(device),
            near=scene.near,
            far=scene.far,
            effects=self.effects,
            max_iters=max_iters,
            generator=generator,
            device=device,
            step_generator=self.step_generator,
        ).to(device)
        self._generator = generator
        self.max_samples = max_training_samples(device)
        """Samples one training pass evaluates at most (a larger batch is taken in chunks)."""
        # Unseen-view rays draw from a stream of their own: turning an unseen-view regulariser on changes the loss,
        # not the training batches or their jitter.
        self.unseen_generator = torch.Generator(device=self.step_generator.device).manual_seed(
            generator.initial_seed() + 2
        )

    def train_step(self, step: int) -> tuple[Tensor, dict[str, Tensor]]:
        """Loss for one batch at ``step`` and the step's metrics, still on the device (``read_metrics`` reads them:
        a GPU step need not wait for them); the grids are filtered once here and reused by every term."""
        with phase("data"):
            batch = self.datamanager.next_batch(step)
        self.model.prepare(step)
        spans = chunk_spans(batch.origins.shape[0], self.model.samples_per_ray(training=True), self.max_samples)
        carrier = None
        if len(spans) > 1:  # a batch too large for one pass (ZeroRF's later ones): its gradient chunk by chunk
            loss_terms, carrier = accumulate_in_chunks(self.model, batch, step, spans)
        else:
            outputs = self.model(batch.origins, batch.directions)
            with phase("losses"):
                loss_terms = self.model.loss_dict(outputs, batch.rgba, step)
        for regulariser in self.model.unseen_views():
            views = regulariser.unseen
            with phase("data"):
                origins, directions = self.datamanager.unseen_patches(views.patches, views.size, self.unseen_generator)
            loss_terms[regulariser.unseen_name] = self.model.unseen_loss(
                regulariser, origins, directions, self.unseen_generator
            )
        with phase("losses"):
            loss = torch.stack(list(loss_terms.values())).sum()
            if carrier is not None:
                loss = loss + carrier
        metrics = {k: v.detach() for k, v in loss_terms.items()}
        metrics["loss"] = loss.detach()
        metrics["psnr"] = -10.0 * torch.log10(metrics["mse"].clamp(min=1e-10))
        revived = self.model.field.revived_batches
        if revived is not None:  # a count so far, logged so that a run says whether revival acted at all
            metrics["revived_batches"] = revived.clone()
        return loss, metrics

    @staticmethod
    def read_metrics(metrics: dict[str, Tensor]) -> dict[str, float]:
        """The metrics of a step as numbers, in one read from the device."""
        values = torch.stack([v.reshape(()).float() for v in metrics.values()]).tolist()
        return dict(zip(metrics, values, strict=True))

    def after_step(self, step: int) -> Changes:
        with phase("structure"):
            changes = self.model.after_step(step)
            if changes.filter_rays:
                before = int(self.datamanager.active.numel())
                after = self.datamanager.keep_rays(self.model.rays_hit_occupancy)
                get_console().print(f"ray filtering: kept {after} of {before} training rays")
        return changes

    def render_views(self, split: Split, step: int, names: Collection[str] = ()) -> Iterator[RenderedView]:
        """Every view of a split (only those in ``names`` when given: the others are not rendered) at the cutoffs of
        ``step``, beside its target on the same background."""
        background = background_color(self.effects.eval_background, 1, self.device, None)
        for view in self.datamanager.eval_views(split):
            if names and view.name not in names:
                continue
            start = time.perf_counter()
            out = self.model.render_rays(view.rays.origins, view.rays.directions, step)
            seconds = time.perf_counter() - start
            shape = (view.height, view.width)
            target = composite_target(view.rays.rgba, background)
            yield RenderedView(
                view,
                out["rgb"].view(*shape, 3).cpu(),
                target.view(*shape, 3).cpu(),
                out["depth"].view(shape).cpu(),
                out["accumulation"].view(shape).cpu(),
                seconds,
            )

    def state_dict(self) -> dict:
        state = {"model": self.model.state_dict(), "datamanager": self.datamanager.state_dict()}
        if self.step_generator is not self._generator:
            state["step_generator"] = self.step_generator.get_state()
        if self.model.config.unseen_rays() > 0:
            state["unseen_generator"] = self.unseen_generator.get_state()
        return state

    def load_state_dict(self, state: dict) -> None:
        self.model.load_state_dict(state["model"])
        if "step_generator" in state and self.step_generator is not self._generator:
            self.step_generator.set_state(state["step_generator"])
        if "unseen_generator" in state:
            self.unseen_generator.set_state(state["unseen_generator"])
        if "datamanager" in state and self.datamanager.load_train:
            self.datamanager.load_state_dict(state["datamanager"])


def check_patch_fits(model: FourieRFModelConfig, width: int, height: int) -> None:
    """One clear error when the unseen-view patches of depth smoothness are larger than the training images."""
    size = model.depth_smoothness_patch_size
    if model.depth_smoothness_weight > 0 and size > min(width, height):
        fail(
            f"--pipeline.model.depth-smoothness-patch-size {size} does not fit the {width}×{height} training images",
            f"pass a patch size of at most {min(width, height)}, or --pipeline.model.depth-smoothness-weight 0",
        )


def step_generator(generator: torch.Generator, device: torch.device, gpu_paths: bool) -> torch.Generator:
    """Where a step's random numbers come from: the run's generator on a CPU (what it always was); on the GPU paths
    a generator of its own on the device, seeded from the run's seed (drawing nothing from it, so the initial grids
    are the same either way), so that batches and jitter are drawn there."""
    if not gpu_paths:
        return generator
    return torch.Generator(device=device).manual_seed(generator.initial_seed() + 1)


@dataclass
class PipelineConfig(InstantiateConfig):
    _target: ClassVar[type] = Pipeline
    datamanager: DataManagerConfig = field(default_factory=DataManagerConfig)
    effects: EffectsConfig = field(default_factory=EffectsConfig)
    """The scene's effects: None = as the scene declares (resolved once, before anything is built)."""
    model: FourieRFModelConfig = field(default_factory=FourieRFModelConfig)
