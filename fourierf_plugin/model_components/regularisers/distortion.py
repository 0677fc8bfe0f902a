"""mip-NeRF 360's distortion loss on the training rays: it pulls each ray's weight into one short interval."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, ClassVar

import torch
from torch import Tensor

from fourierf_plugin.data.scene_effects import SceneEffects
from fourierf_plugin.model_components.regularisers.base import Regulariser, TrainingRays


def distortion(weights: Tensor, s: Tensor) -> Tensor:
    """The loss, mean over rays: ``Σ_ij w_i w_j |m_i - m_j| + Σ_i w_i² d_i / 3``.

    Why: few-shot fields spread each ray's weight over several depths (floaters, doubled geometry); this term is
    smallest when the weight sits in one short interval. ``s`` [R, N] are ascending sample positions in normalised
    ray distance (0 at the near end, 1 at the far end); sample i stands for the interval [s_i, s_{i+1}] (the last
    for none, as its compositing interval is 0), m its midpoint, d its length. The pairwise sum is taken in O(N)
    from exclusive prefix sums of w and w m. 0, not NaN, for no rays.
    """
    if weights.shape[0] == 0:
        return weights.sum()
    lengths = torch.cat([s.diff(dim=-1), torch.zeros_like(s[..., :1])], dim=-1)
    mids = s + 0.5 * lengths
    wm = weights * mids
    w_before = torch.cumsum(weights, dim=-1) - weights
    wm_before = torch.cumsum(wm, dim=-1) - wm
    pairwise = 2.0 * (wm * w_before - weights * wm_before).sum(dim=-1)
    own = (weights.square() * lengths).sum(dim=-1) / 3.0
    return (pairwise + own).mean()


@dataclass(frozen=True)
class Distortion(Regulariser):
    """``distortion_weight`` × the loss over each training batch, in ray distance normalised from near to far."""

    name: ClassVar[str] = "distortion"
    weight: float

    @classmethod
    def from_model(cls, config: Any, effects: SceneEffects, max_iters: int) -> Distortion | None:
        return cls(config.distortion_weight) if config.distortion_weight > 0 else None

    def ray_term(self, rays: TrainingRays) -> Tensor:
        return distortion(rays.weights, (rays.t - rays.near) / (rays.far - rays.near))
