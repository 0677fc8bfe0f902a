"""RegNeRF's depth smoothness on patches seen from poses between the training cameras: density that paints each photo
from just in front of its camera leaves the depth torn between the views."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, ClassVar

from torch import Tensor

from fourierf_plugin.data.scene_effects import SceneEffects
from fourierf_plugin.model_components.regularisers.base import Regulariser, UnseenViews


def depth_smoothness(depth: Tensor) -> Tensor:
    """The mean squared difference between vertical neighbours of patches [P, S, S] plus that between horizontal ones
    (0 for a constant patch, and 0, not NaN, for no patches)."""
    if depth.shape[0] == 0:
        return depth.sum()
    return depth.diff(dim=1).square().mean() + depth.diff(dim=2).square().mean()


@dataclass(frozen=True)
class DepthSmoothness(Regulariser):
    """``depth_smoothness_weight`` × the term on ``depth_smoothness_patches`` unseen patches a step."""

    name: ClassVar[str] = "depth_smoothness"
    unseen_name: ClassVar[str] = "depth_smoothness"
    weight: float
    unseen: UnseenViews

    @classmethod
    def from_model(cls, config: Any, effects: SceneEffects, max_iters: int) -> DepthSmoothness | None:
        if config.depth_smoothness_weight <= 0:
            return None
        views = UnseenViews(config.depth_smoothness_patches, config.depth_smoothness_patch_size)
        return cls(config.depth_smoothness_weight, views)

    def unseen_loss(self, outputs: dict) -> Tensor:
        size = self.unseen.size
        return self.weight * depth_smoothness(outputs["depth"].view(-1, size, size))
