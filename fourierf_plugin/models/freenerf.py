"""FreeNeRF as a model of this pipeline: an MLP radiance field (``fields.mlp_field``) whose positional encoding's
visible bands open linearly over FreeNeRF's share of the run, with FreeNeRF's occlusion regulariser.

Two samplers. With ``samples_per_level`` set (FreeNeRF's LLFF runs), FreeNeRF's own: mip-NeRF's two levels through
the one MLP, stratified intervals from near to far, then intervals drawn from the first level's blurred weights, each
level's colour scored (the first at ``coarse_loss_weight``) and the occlusion term on the second, as FreeNeRF trains
them. Without it (the Blender preset), this pipeline's: jittered steps of ``step_ratio`` voxels of the occupancy grid
through the scene's box, the occupancy grid skipping empty space from its first update on, which puts the samples
where the density is for fewer evaluations than a second level on an object's mostly empty box. In CPU training the
colour reads the trunk's output of the density pass, so each sample goes through the trunk once, as in NeRF.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Collection
from dataclasses import dataclass
from typing import Any, ClassVar, NamedTuple

import torch
from torch import Tensor

from fourierf_plugin.data.scene_effects import SceneEffects
from fourierf_plugin.field_components import schedules
from fourierf_plugin.field_components.frequency_mask import visible_share
from fourierf_plugin.fields.mlp_field import MLPField, MLPFieldConfig
from fourierf_plugin.fields.prepared_field import PreparedField
from fourierf_plugin.model_components import losses
from fourierf_plugin.model_components.marching import occupied, shade
from fourierf_plugin.model_components.ray_sampling import RaySamples
from fourierf_plugin.model_components.regularisers import TrainingRays
from fourierf_plugin.model_components.rendering import composite_target, composite_weights
from fourierf_plugin.model_components.resampling import (
    blurred_weights,
    midpoints_and_lengths,
    sample_histogram,
    stratified_edges,
)
from fourierf_plugin.models.fourierf import FourierConfig, FourieRFModel, FourieRFModelConfig

LEVELS = 2
"""FreeNeRF's sampling levels (mip-NeRF's): a stratified one, then one drawn from its weights."""


class Level(NamedTuple):
    """One sampling level of a batch of R rays, N samples each: ray parameters, δ, σ, compositing weights and the
    samples' colours ([R, N, 3], None for a geometry-only render)."""

    t: Tensor
    deltas: Tensor
    sigma: Tensor
    weights: Tensor
    rgb: Tensor | None


class FreeNeRFModel(FourieRFModel):
    config: FreeNeRFModelConfig

    def _build_field(
        self, scene_box: Tensor, effects: SceneEffects, generator: torch.Generator, device: torch.device | str
    ) -> PreparedField:
        """The MLP field, its encoding box the scene's box, its sampling grid the run's initial one."""
        size = (scene_box[1] - scene_box[0]).tolist()
        reso = schedules.n_to_reso(self.config.field.n_voxels_init, size)
        return MLPField(self.config.mlp, scene_box, reso, effects.view_dependent, generator, self.step_generator)

    def march(self, samples: RaySamples) -> Tensor:
        """σ [R, N] as any model marches; in CPU training the trunk's output at the occupied samples is kept for
        ``colours`` (the sampler's other paths evaluate the trunk again for the colour)."""
        field: MLPField = self.field  # type: ignore[assignment]
        field.recorded = None
        field.recording = self.training and not self.gpu_paths and self.config.cull_weight_threshold <= 0
        try:
            return super().march(samples)
        finally:
            field.recording = False

    def colours(self, samples: RaySamples, weights: Tensor, scale: Tensor | None) -> Tensor:
        """Ray colours from the trunk's output ``march`` kept (the samples that show are among the occupied ones it
        evaluated, in the same order), else as any model."""
        field: MLPField = self.field  # type: ignore[assignment]
        trunk, field.recorded = field.recorded, None
        if trunk is None:
            return super().colours(samples, weights, scale)
        points = samples.points.view(-1, 3)
        evaluated, _ = occupied(points, samples.inside.view(-1).nonzero().squeeze(1), self.occupancy)
        threshold = self.config.weight_threshold
        shown = (weights.detach().view(-1) > threshold).nonzero().squeeze(1)
        rows = torch.searchsorted(evaluated, shown).clamp(max=max(0, evaluated.numel() - 1))
        if evaluated.numel() == 0 or not torch.equal(evaluated.index_select(0, rows), shown):
            return super().colours(samples, weights, scale)

        def colour(_points: Tensor, directions: Tensor | None) -> Tensor:
            return field.rgb_from_trunk(trunk.index_select(0, rows), directions)

        return shade(colour, samples, weights, threshold, self.effects.view_dependent, scale)

    # -- FreeNeRF's own sampler: two levels through the one MLP ------------------------------------------------
    def set_run_length(self, max_iters: int) -> None:
        """As any model; with two levels no occupancy grid is used, so neither its updates nor the upsamples of the
        grid it steps are scheduled."""
        super().set_run_length(max_iters)
        if self.config.samples_per_level:
            self.upsample_steps, self.voxel_targets, self.occupancy_steps = [], [], []
            self.after_first_update = None
            self.random_background_step = self._random_background_step()

    def samples_per_ray(self, training: bool) -> int:
        levels = self.config.samples_per_level
        return LEVELS * levels if levels else super().samples_per_ray(training)

    def forward(
        self,
        origins: Tensor,
        directions: Tensor,
        background: Tensor | None = None,
        jitter: torch.Generator | None = None,
        colour: bool = True,
        terms: Collection[str] | None = None,
    ) -> dict:
        """As any model renders (``FourieRFModel.forward``); with ``samples_per_level``, through FreeNeRF's two
        levels: the last one's render, and in training the first one's colour (``rgb_coarse``) for its loss."""
        if not self.config.samples_per_level:
            return super().forward(origins, directions, background, jitter, colour, terms)
        if background is None:
            background = self.draw_background(origins.shape[0], origins.device)
        generator = (jitter or self.step_generator) if self.training else None
        coarse, fine = self._levels(origins, directions, generator, colour)
        out = self._composite(fine, background)
        if self.training:
            out["rgb_coarse"] = self._composite(coarse, background)["rgb"]
            rays = TrainingRays(
                fine.sigma, fine.t, fine.deltas, fine.weights, out["accumulation"], self.near, self.far,
                self.config.distance_scale,
            )  # fmt: skip
            out |= self.ray_terms(rays, terms)
        return out

    def _levels(
        self, origins: Tensor, directions: Tensor, generator: torch.Generator | None, colour: bool
    ) -> list[Level]:
        """The two levels' samples through the MLP: stratified intervals from near to far, then intervals drawn from
        the first level's blurred weights (no gradient flows through the drawing, as in mip-NeRF)."""
        field: MLPField = self.field  # type: ignore[assignment]
        num, c = origins.shape[0], self.config
        length = directions.norm(dim=-1, keepdim=True)  # NDC directions are not unit: δ is scaled by |d|
        view = (directions / length).unsqueeze(1).expand(num, c.samples_per_level, 3).reshape(-1, 3)
        edges = stratified_edges(self.near, self.far, num, c.samples_per_level + 1, generator, origins.device)
        levels: list[Level] = []
        for _ in range(LEVELS):
            if levels:
                histogram = blurred_weights(levels[-1].weights.detach(), c.resample_padding)
                edges = sample_histogram(edges, histogram, c.samples_per_level + 1, generator)
            t, spans = midpoints_and_lengths(edges)
            points = torch.addcmul(origins.unsqueeze(1), directions.unsqueeze(1), t.unsqueeze(-1)).view(-1, 3)
            if colour:
                sigma, rgb = field.radiance(points, view if self.effects.view_dependent else None)
            else:
                sigma, rgb = field.density(points), None
            sigma, deltas = sigma.view(num, -1), spans * length
            weights = composite_weights(sigma, deltas, c.distance_scale)
            levels.append(Level(t, deltas, sigma, weights, None if rgb is None else rgb.view(num, -1, 3)))
        return levels

    def _composite(self, level: Level, background: Tensor) -> dict[str, Tensor]:
        """A level's render (``composite``) from its samples' colours (none: a geometry-only render)."""
        weights = level.weights
        rgb = weights.new_zeros(weights.shape[0], 3)
        if level.rgb is not None:
            rgb = (weights.unsqueeze(-1) * level.rgb).sum(dim=1)
        return self.composite(rgb, weights, level.t, background)

    def loss_dict(self, outputs: dict, target_rgba: Tensor, step: int) -> dict[str, Tensor]:
        """Any model's terms on the render, and with two levels the first level's MSE at ``coarse_loss_weight``."""
        out = super().loss_dict(outputs, target_rgba, step)
        if "rgb_coarse" in outputs and self.config.coarse_loss_weight > 0:
            target = composite_target(target_rgba, outputs["background"])
            out["mse_coarse"] = self.config.coarse_loss_weight * losses.mse(outputs["rgb_coarse"], target)
        return out

    def cutoffs(self, step: int) -> tuple[float, float]:
        """The share of the encoding's bands visible at ``step`` (positions and directions alike): FreeNeRF's t / T."""
        share = visible_share(step, round(self.config.mlp.ramp_fraction * self.max_iters))
        return share, share


@dataclass
class FreeNeRFModelConfig(FourieRFModelConfig):
    """FreeNeRF (Jiawei-Yang/FreeNeRF): its MLP and frequency mask (``mlp``), its occlusion term (weight 0.01 on the
    first 20 of 128 samples of each ray), compositing ``1 - exp(-σδ)`` (no distance scale), no TV and no L1 (those are
    a grid's). ``field`` gives only the sampling and occupancy grid's size and schedule (neither is used with two
    levels); the Fourier curriculum of the grids is off (the encoding's mask is FreeNeRF's curriculum)."""

    _target: ClassVar[type] = FreeNeRFModel
    mlp: MLPFieldConfig = dataclasses.field(default_factory=MLPFieldConfig)
    """FreeNeRF's network and frequency regularisation."""
    fourier: FourierConfig = dataclasses.field(default_factory=lambda: FourierConfig(enabled=False))
    distance_scale: float = 1.0
    step_ratio: float = 1.0
    """Sampling step in voxels of the occupancy grid (one voxel: about FreeNeRF's 64 + 128 samples per ray on a CPU
    run's final grid)."""
    tv_weight_density: float = 0.0
    tv_weight_appearance: float = 0.0
    l1_weight_initial: float = 0.0
    l1_weight_rest: float = 0.0
    occlusion_weight: float = 0.01
    occlusion_fraction: float = 20 / 128
    samples_per_level: int = 0
    """Samples per ray on each of FreeNeRF's two levels (its LLFF runs, mip-NeRF's sampler: 128); 0 marches the
    occupancy grid instead (``step_ratio``)."""
    coarse_loss_weight: float = 0.1
    """The weight of the first level's photometric term, the second's being 1 (mip-NeRF, FreeNeRF: 0.1)."""
    resample_padding: float = 0.01
    """Added to the first level's blurred weights before the second level is drawn from them (mip-NeRF: 0.01)."""


def mlp_config(model: Any) -> MLPFieldConfig | None:
    """The MLP's config of a model config whose field is an MLP (FreeNeRF), else None."""
    return model.mlp if isinstance(model, FreeNeRFModelConfig) else None


GRID_ONLY_OPTIONS = ("tv_weight_density", "tv_weight_appearance", "l1_weight_initial", "l1_weight_rest")
"""Model options that act on factor grids: an MLP field has none to regularise."""
