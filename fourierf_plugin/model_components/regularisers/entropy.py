"""InfoNeRF's ray entropy, on the training rays and on rays from poses between the training cameras: it pulls each
ray's opacity into one sample, and charges the fog seen only from between the cameras, which no photo does."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, ClassVar

import torch
from torch import Tensor

from fourierf_plugin.data.scene_effects import SceneEffects
from fourierf_plugin.model_components.regularisers.base import Regulariser, TrainingRays, UnseenViews
from fourierf_plugin.model_components.rendering import opacity_from_density


def ray_entropy(alpha: Tensor, accumulation: Tensor, threshold: float) -> Tensor:
    """The entropy in bits, summed over the rays whose accumulation exceeds ``threshold`` and divided by all rays:
    ``-Σ_i p_i log2 p_i`` with ``p_i = α_i / Σ_j α_j`` the ray's opacity, normalised.

    Why: a few-shot field explains each view with density spread along the ray (fog, floaters); the entropy is 0
    when a ray's opacity sits in one sample and log2 N when it is even over N. Rays that hit nothing are left out, so
    empty space is not pushed to gather an opaque sample. Only those rays enter the logarithm: a masked-out ray has
    no gradient, not a NaN. 0 for no rays.
    """
    if alpha.shape[0] == 0:
        return alpha.sum()
    hit = alpha[accumulation > threshold]
    p = hit / hit.sum(dim=-1, keepdim=True).clamp(min=1e-10)
    entropy = -(p * torch.log2(p + 1e-10)).sum()
    return entropy / alpha.shape[0]


@dataclass(frozen=True)
class Entropy(Regulariser):
    """``entropy_weight`` × the entropy of each training batch and of ``entropy_unseen_rays`` single rays from unseen
    poses (each a 1-pixel patch, so a pose of its own)."""

    name: ClassVar[str] = "entropy"
    unseen_name: ClassVar[str] = "entropy_unseen"
    weight: float
    threshold: float
    """Rays whose accumulation is at most this hit nothing and are left out (InfoNeRF: 0.1)."""
    unseen: UnseenViews | None

    @classmethod
    def from_model(cls, config: Any, effects: SceneEffects, max_iters: int) -> Entropy | None:
        if config.entropy_weight <= 0:
            return None
        views = UnseenViews(config.entropy_unseen_rays, 1) if config.entropy_unseen_rays > 0 else None
        return cls(config.entropy_weight, config.entropy_threshold, views)

    def ray_term(self, rays: TrainingRays) -> Tensor:
        alpha = opacity_from_density(rays.sigma, rays.deltas, rays.distance_scale)
        return ray_entropy(alpha, rays.accumulation, self.threshold)

    def unseen_loss(self, outputs: dict) -> Tensor:
        return self.weight * outputs[self.name]
