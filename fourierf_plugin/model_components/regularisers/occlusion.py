"""FreeNeRF's occlusion regulariser: density right in front of the cameras is penalised, where few-shot training
likes to paint floaters."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, ClassVar

from torch import Tensor

from fourierf_plugin.data.scene_effects import SceneEffects
from fourierf_plugin.model_components.regularisers.base import Regulariser, TrainingRays


def occlusion_penalty(sigma: Tensor, fraction: float, distance_scale: float) -> Tensor:
    """Mean over rays and all K samples of σ_k · 1[k < M], M = round(fraction · K).

    FreeNeRF composites ``1 - exp(-σ δ)``, this pipeline ``1 - exp(-distance_scale · σ δ)``: the term is on FreeNeRF's
    σ, ``distance_scale · σ``, so its weight means what it means there.
    """
    k = sigma.shape[-1]
    if sigma.shape[0] == 0 or k == 0:
        return sigma.sum()  # no rays: 0 with a graph, not the NaN of an empty mean
    m = max(1, round(fraction * k))
    return distance_scale * sigma[:, :m].sum(dim=-1).mean() / k


@dataclass(frozen=True)
class Occlusion(Regulariser):
    """``occlusion_weight`` × the penalty on each training batch, on scenes that ask for it (forward-facing)."""

    name: ClassVar[str] = "occlusion"
    weight: float
    fraction: float
    """Share of each ray, from its start, whose densities are penalised (FreeNeRF: 20 of 128)."""

    @classmethod
    def from_model(cls, config: Any, effects: SceneEffects, max_iters: int) -> Occlusion | None:
        if not effects.occlusion_regularization or config.occlusion_weight <= 0:
            return None
        return cls(config.occlusion_weight, config.occlusion_fraction)

    def ray_term(self, rays: TrainingRays) -> Tensor:
        return occlusion_penalty(rays.sigma, self.fraction, rays.distance_scale)
