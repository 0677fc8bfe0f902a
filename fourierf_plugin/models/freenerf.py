"""FreeNeRF as a model of this pipeline: an MLP radiance field (``fields.mlp_field``) whose positional encoding's
visible bands open linearly over FreeNeRF's share of the run, with FreeNeRF's occlusion regulariser.

Sampling is this pipeline's, not FreeNeRF's coarse and fine networks: jittered steps of ``step_ratio`` voxels of the
occupancy grid through the scene's box (even steps of NDC depth on a forward-facing scene), with the occupancy grid
skipping empty space from its first update on. One network instead of two halves the parameters and the cost per
sample, and the occupancy grid replaces the fine pass's job of putting samples where the density is. In CPU training
the colour reads the trunk's output of the density pass, so each sample goes through the trunk once, as in NeRF.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import Any, ClassVar

import torch
from torch import Tensor

from fourierf_plugin.data.scene_effects import SceneEffects
from fourierf_plugin.field_components import schedules
from fourierf_plugin.field_components.frequency_mask import visible_share
from fourierf_plugin.fields.mlp_field import MLPField, MLPFieldConfig
from fourierf_plugin.fields.prepared_field import PreparedField
from fourierf_plugin.model_components.marching import occupied, shade
from fourierf_plugin.model_components.ray_sampling import RaySamples
from fourierf_plugin.models.fourierf import FourierConfig, FourieRFModel, FourieRFModelConfig


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

    def cutoffs(self, step: int) -> tuple[float, float]:
        """The share of the encoding's bands visible at ``step`` (positions and directions alike): FreeNeRF's t / T."""
        share = visible_share(step, round(self.config.mlp.ramp_fraction * self.max_iters))
        return share, share


@dataclass
class FreeNeRFModelConfig(FourieRFModelConfig):
    """FreeNeRF (Jiawei-Yang/FreeNeRF): its MLP and frequency mask (``mlp``), its occlusion term (weight 0.01 on the
    first 20 of 128 samples of each ray), compositing ``1 - exp(-σδ)`` (no distance scale), no TV and no L1 (those are
    a grid's). ``field`` gives only the sampling and occupancy grid's size and schedule; the Fourier curriculum of the
    grids is off (the encoding's mask is FreeNeRF's curriculum)."""

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


def mlp_config(model: Any) -> MLPFieldConfig | None:
    """The MLP's config of a model config whose field is an MLP (FreeNeRF), else None."""
    return model.mlp if isinstance(model, FreeNeRFModelConfig) else None


GRID_ONLY_OPTIONS = ("tv_weight_density", "tv_weight_appearance", "l1_weight_initial", "l1_weight_rest")
"""Model options that act on factor grids: an MLP field has none to regularise."""
