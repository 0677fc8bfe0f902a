"""ZeroRF's silhouette supervision: where the scene's images carry alpha, each training ray's opacity (its
accumulation) is fitted to its pixel's alpha beside the colour, so empty space is charged on every background pixel
whatever the background's colour."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, ClassVar

from torch import Tensor

from fourierf_plugin.data.scene_effects import SceneEffects
from fourierf_plugin.model_components.regularisers.base import Regulariser
from fourierf_plugin.utils.errors import fail

TARGET_ALPHA = "target_alpha"
"""Key of the training batch's target alpha [R] among the outputs the regularisers' ``loss`` reads (the model that
builds this term puts it there: ``models.zerorf.ZeroRFModel.loss_dict``)."""

ZERORF_ALPHA_WEIGHT = 1.0 / 3.0
"""ZeroRF's weight of the alpha term against this pipeline's RGB MSE. Its pixel loss on an RGBA target is one MSE over
the four channels, the rendered accumulation appended to the colour as the fourth (eliphatfs/zerorf,
``lib/models/autoencoders/base_nerf.py``, ``BaseNeRF.loss``): (3 · MSE_rgb + MSE_alpha) / 4 = 3/4 · (MSE_rgb +
MSE_alpha / 3), MSE_rgb the mean over three channels as here. The common 3/4 only rescales the loss, which AdamW
does not see."""


def alpha_mse(accumulation: Tensor, alpha: Tensor) -> Tensor:
    """Mean over rays of (accumulation − alpha)²: 0 where every ray's opacity equals its pixel's alpha; 0 with a graph
    for no rays (not the NaN of an empty mean)."""
    if accumulation.numel() == 0:
        return accumulation.sum()
    return (accumulation - alpha.to(accumulation.dtype)).square().mean()


@dataclass(frozen=True)
class Alpha(Regulariser):
    """``alpha_weight`` × ``alpha_mse`` on each training batch, on scenes whose background is known (alpha or masks:
    white, black or random); off on photos (background "none"), whose alpha is 1 everywhere and marks no
    background. Its term is on the loss only (the render needs the target, which ``ray_term`` does not see)."""

    name: ClassVar[str] = "alpha"
    weight: float

    @classmethod
    def from_model(cls, config: Any, effects: SceneEffects, max_iters: int) -> Alpha | None:
        weight = config.alpha_weight
        if not weight >= 0:
            fail(
                f"--pipeline.model.alpha-weight {weight} is out of range: it must be a weight >= 0 (0 = off)",
                f"pass e.g. --pipeline.model.alpha-weight {ZERORF_ALPHA_WEIGHT:.6g} (ZeroRF's)",
            )
        if effects.background == "none" or weight == 0:
            return None
        return cls(weight)

    def loss(self, outputs: dict) -> Tensor | None:
        if TARGET_ALPHA not in outputs:
            return None
        return self.weight * alpha_mse(outputs["accumulation"], outputs[TARGET_ALPHA])
