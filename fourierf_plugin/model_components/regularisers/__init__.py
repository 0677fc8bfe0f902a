"""The few-shot regularisers, one module each; ``build`` gives those a model config asks for, in the order their terms
are taken (training-ray terms first to last, then the unseen-view terms in the same order). ZeroRF's alpha term
(``alpha``) needs the target's alpha, which only ZeroRF's model hands its regularisers: its config adds it."""

from __future__ import annotations

from typing import Any

from fourierf_plugin.data.scene_effects import SceneEffects
from fourierf_plugin.model_components.regularisers.alpha import Alpha
from fourierf_plugin.model_components.regularisers.base import Regulariser, TrainingRays, UnseenViews
from fourierf_plugin.model_components.regularisers.depth_smoothness import DepthSmoothness
from fourierf_plugin.model_components.regularisers.distortion import Distortion
from fourierf_plugin.model_components.regularisers.entropy import Entropy
from fourierf_plugin.model_components.regularisers.floaters import FloatersNoMore
from fourierf_plugin.model_components.regularisers.occlusion import Occlusion

__all__ = [
    "KINDS",
    "Alpha",
    "DepthSmoothness",
    "Distortion",
    "Entropy",
    "FloatersNoMore",
    "Occlusion",
    "Regulariser",
    "TrainingRays",
    "UnseenViews",
    "build",
]

KINDS: tuple[type, ...] = (FloatersNoMore, Occlusion, Distortion, DepthSmoothness, Entropy)
"""Every regulariser, in the order the model takes their terms."""


def build(config: Any, effects: SceneEffects, max_iters: int) -> list[Regulariser]:
    """The regularisers ``config`` (a model config's flat options) turns on for a scene with ``effects``."""
    built = (kind.from_model(config, effects, max_iters) for kind in KINDS)
    return [regulariser for regulariser in built if regulariser is not None]
