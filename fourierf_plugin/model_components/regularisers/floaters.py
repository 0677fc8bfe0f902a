"""'Floaters No More': identity forward, density and colour gradients scaled by clamp(t², 0, 1) backward.

Samples close to the camera get small gradients, so the few views cannot explain their pixels with near floaters. It
acts where samples lie within 1 of the camera (NDC, forward-facing); past Blender's near plane 2 it does nothing.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, ClassVar

from torch import Tensor

from fourierf_plugin.data.scene_effects import SceneEffects
from fourierf_plugin.model_components.regularisers.base import Regulariser


def floaters_scale(t: Tensor) -> Tensor:
    """The factor clamp(t², 0, 1) for ray parameters ``t``."""
    return (t * t).clamp(0.0, 1.0)


@dataclass(frozen=True)
class FloatersNoMore(Regulariser):
    """Gradient scaling from ``from_step`` on (``floaters_gradient_scaling``, ``floaters_gradient_scaling_from``)."""

    name: ClassVar[str] = "floaters"
    from_step: int

    @classmethod
    def from_model(cls, config: Any, effects: SceneEffects, max_iters: int) -> FloatersNoMore | None:
        if not config.floaters_gradient_scaling:
            return None
        return cls(round(config.floaters_gradient_scaling_from * max_iters))

    def scales_gradients_at(self, step: int) -> bool:
        return step >= self.from_step

    def gradient_scale(self, t: Tensor) -> Tensor:
        return floaters_scale(t)
