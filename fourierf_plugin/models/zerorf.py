"""ZeroRF as a model of its own: the FourieRF/TensoRF pipeline with the VM factors generated from fixed noise by
ZeroRF's networks and read by ZeroRF's decoder (``fields.zerorf_field``), at ZeroRF's published settings."""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import Any, ClassVar

import torch
from torch import Tensor

from fourierf_plugin.accel import build_ops
from fourierf_plugin.data.scene_effects import SceneEffects
from fourierf_plugin.field_components import schedules
from fourierf_plugin.field_components.generator import ZeroRFConfig
from fourierf_plugin.fields.prepared_field import PreparedField
from fourierf_plugin.fields.zerorf_field import ZeroRFField
from fourierf_plugin.model_components.regularisers import Regulariser
from fourierf_plugin.model_components.regularisers.alpha import TARGET_ALPHA, ZERORF_ALPHA_WEIGHT, Alpha
from fourierf_plugin.models.fourierf import FourierConfig, FourieRFModel, FourieRFModelConfig


class ZeroRFModel(FourieRFModel):
    config: ZeroRFModelConfig

    def _build_field(
        self, scene_box: Tensor, effects: SceneEffects, generator: torch.Generator, device: torch.device | str
    ) -> PreparedField:
        """ZeroRF's field, its canvas sized for the finest grid of the run."""
        config, fc = self.config, self.config.field
        size = (scene_box[1] - scene_box[0]).tolist()
        reso = schedules.n_to_reso(fc.n_voxels_init, size)
        final = schedules.n_to_reso(max([fc.n_voxels_init, *self.voxel_targets]), size)
        ops = build_ops(config.accel, device)
        leakage, mirror = config.fourier.plane_leakage, config.fourier.boundary == "mirror"
        return ZeroRFField(
            config.zerorf, scene_box, reso, final, effects.view_dependent, generator, ops, leakage, mirror
        )

    def loss_dict(self, outputs: dict, target_rgba: Tensor, step: int) -> dict[str, Tensor]:
        """FourieRF's terms, with the target's alpha handed to the regularisers beside the render (ZeroRF's alpha
        term reads it there)."""
        return super().loss_dict({**outputs, TARGET_ALPHA: target_rgba[..., 3]}, target_rgba, step)


@dataclass
class ZeroRFModelConfig(FourieRFModelConfig):
    """ZeroRF (eliphatfs/zerorf, ``zerorf.py``, ``--rep tensorf``): generated VM factors, its decoder, its pixel loss
    (the colour, and the opacity fitted to the image's alpha where the scene has one; its TV loss weight is 0; it has
    no L1 and no occlusion term, even where a scene asks for FreeNeRF's), the curriculum off, no distance scale (its
    renderer composites ``1 - exp(-σδ)``) and its occlusion culling in training (gradients only where a sample's
    weight exceeds 1e-4). ``field`` gives the grid's size and schedule only."""

    _target: ClassVar[type] = ZeroRFModel
    zerorf: ZeroRFConfig = dataclasses.field(default_factory=ZeroRFConfig)
    """ZeroRF's generators and decoder."""
    fourier: FourierConfig = dataclasses.field(default_factory=lambda: FourierConfig(enabled=False))
    tv_weight_density: float = 0.0
    tv_weight_appearance: float = 0.0
    l1_weight_initial: float = 0.0
    l1_weight_rest: float = 0.0
    occlusion_weight: float = 0.0
    distance_scale: float = 1.0
    cull_weight_threshold: float = 1e-4
    alpha_weight: float = ZERORF_ALPHA_WEIGHT
    """Weight of ZeroRF's alpha term, (accumulation − alpha)² over the training rays, on scenes whose images carry
    alpha (a white, black or random background; off for photos): ZeroRF's 1/3 against the RGB MSE
    (``regularisers.alpha``); 0 = off."""

    def regularisers(self, effects: SceneEffects, max_iters: int) -> list[Regulariser]:
        """FourieRF's regularisers these options turn on, then ZeroRF's alpha term where the scene has alpha."""
        alpha = Alpha.from_model(self, effects, max_iters)
        return [*super().regularisers(effects, max_iters), *([alpha] if alpha is not None else [])]


def generator_config(model: Any) -> ZeroRFConfig | None:
    """The generators' config of a model config whose factors are generated (ZeroRF), else None."""
    return model.zerorf if isinstance(model, ZeroRFModelConfig) else None
