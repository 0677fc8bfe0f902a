"""Scene-dependent presets: the paper tunes FourieRF differently for synthetic and for real (forward-facing) scenes.

A method preset is written for synthetic scenes; on a forward-facing scene the real-scene values replace every
setting the user left at the preset's default (a flag given on the command line always wins).
"""

from __future__ import annotations

from typing import Any

REAL_SCENE_SETTINGS: dict[str, Any] = {
    # The curriculum starts almost DC-only and opens over the whole run (paper, real scenes: f0 0.01, δ = 1/N).
    "pipeline.model.fourier.f0_density": 0.01,
    "pipeline.model.fourier.f0_color": 0.01,
    "pipeline.model.fourier.ramp_fraction": 1.0,
    # Density L1 instead of weight decay on real scenes (paper, supplement B).
    "pipeline.model.l1_weight_initial": 1e-4,
    "pipeline.model.l1_weight_rest": 1e-4,
    "optimizer.weight_decay": 0.0,
    # TensoRF's LLFF density activation (spec §3.1, §4.7): softplus(x - 10) starts a real scene nearly empty, and on
    # fern it sat at PSNR ~5 for ~50 iterations; ReLU gets density from the first step (PSNR 15 by step 45).
    "pipeline.model.field.density_activation": "relu",
    # TensoRF's LLFF schedule: one occupancy update at 10 %, upsamples at 8/12/16/22 % of the run.
    "pipeline.model.occupancy_update_fractions": (0.1,),
    "pipeline.model.field.upsample_fractions": (0.08, 0.12, 0.16, 0.22),
}
VM_REAL_SCENE_SETTINGS: dict[str, Any] = {
    # TensoRF's LLFF component counts (the xy plane, facing the cameras, gets the most).
    "pipeline.model.field.density_components": (16, 4, 4),
    "pipeline.model.field.appearance_components": (48, 12, 12),
}


def _get(obj: Any, path: str) -> Any:
    for part in path.split("."):
        obj = getattr(obj, part)
    return obj


def _set(obj: Any, path: str, value: Any) -> None:
    *parents, leaf = path.split(".")
    for part in parents:
        obj = getattr(obj, part)
    setattr(obj, leaf, value)


SCHEDULE_SETTINGS = ("pipeline.model.occupancy_update_fractions", "pipeline.model.field.upsample_fractions")
"""The real-scene values that are the pipeline's, not the method's: a generated field (zerorf-vm) takes only these and
keeps its own loss and optimiser (ZeroRF's weight decay, no L1): the paper compares it at its published settings."""


def real_scene_settings(config: Any) -> dict[str, Any]:
    if config.pipeline.model.field.zerorf.enabled:
        return {path: REAL_SCENE_SETTINGS[path] for path in SCHEDULE_SETTINGS}
    settings = dict(REAL_SCENE_SETTINGS)
    if config.pipeline.model.field.decomposition == "vm":
        settings |= VM_REAL_SCENE_SETTINGS
    return settings


def apply_real_scene_preset(
    config: Any, pristine: Any | None, given: frozenset[str] = frozenset()
) -> tuple[list[str], list[str]]:
    """Set the real-scene values where ``config`` still equals ``pristine`` (the unmodified method preset) and the
    user typed no flag (``given``)."""
    return apply_settings(config, pristine, real_scene_settings(config), given)


def apply_settings(
    config: Any, pristine: Any | None, settings: dict[str, Any], given: frozenset[str] = frozenset()
) -> tuple[list[str], list[str]]:
    """Set each ``settings`` value (config path -> value) where ``config`` still equals ``pristine`` and its path is
    not among ``given``, the paths of the flags the user typed: a flag typed with the preset's own value (say
    ``--max-num-iterations 10000``) wins too, though the config alone cannot tell it from the default.

    Returns the settings applied and the ones kept because the user set them. Without a pristine preset (a
    third-party method) every value not given is applied.
    """
    applied, kept = [], []
    for path, value in settings.items():
        if path in given or (pristine is not None and _get(config, path) != _get(pristine, path)):
            kept.append(path)
            continue
        _set(config, path, value)
        applied.append(f"{path.rsplit('.', 1)[-1]}={value}")
    return applied, kept
