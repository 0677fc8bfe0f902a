"""The model options the regularisers are built from, as a plain namespace (the model config's defaults)."""

from __future__ import annotations

from types import SimpleNamespace

DEFAULTS = {
    "occlusion_weight": 0.01,
    "occlusion_fraction": 20 / 128,
    "floaters_gradient_scaling": False,
    "floaters_gradient_scaling_from": 0.0,
    "distortion_weight": 0.0,
    "depth_smoothness_weight": 0.0,
    "depth_smoothness_patches": 4,
    "depth_smoothness_patch_size": 8,
    "entropy_weight": 0.0,
    "entropy_threshold": 0.1,
    "entropy_unseen_rays": 1024,
}


def options(**changes: object) -> SimpleNamespace:
    """The model config's regulariser options with ``changes``."""
    return SimpleNamespace(**(DEFAULTS | changes))
