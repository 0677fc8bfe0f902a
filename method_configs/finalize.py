"""From what a user typed to the finished config a ``Trainer`` takes, and back from a saved run.

Everything that depends on the scene is decided here, once, before anything is built: the scene's declared effects
combined with the user's overrides, and the synthetic or real-scene preset. The trainer, pipeline and model only
read the result, and ``config.json`` records it.
"""

from __future__ import annotations

import copy
from pathlib import Path

from fourierf_plugin.configs.base import config_classes, load_config
from fourierf_plugin.data.scene_effects import EffectsConfig
from fourierf_plugin.engine.trainer import TrainerConfig
from fourierf_plugin.method_configs.registry import all_methods
from fourierf_plugin.method_configs.scene_presets import apply_real_scene_preset
from fourierf_plugin.utils.errors import fail


def config_registry() -> dict[str, type]:
    """Every config class a saved run may name: the built-in ones and those of installed plugins (importing this
    module imported them all)."""
    return config_classes()


def finalize(config: TrainerConfig) -> tuple[TrainerConfig, list[str]]:
    """A copy of ``config`` with ``--data`` in its parser, the scene preset applied and the scene's effects resolved;
    and the notes that say what was decided and why (for the caller to print)."""
    config = copy.deepcopy(config)
    if config.data is not None:
        config.pipeline.datamanager.dataparser.data = config.data
    declared = config.pipeline.datamanager.dataparser.setup().declaration()
    notes = []
    preset = config.scene_preset
    if preset == "auto":
        preset = "synthetic" if declared.bounded else "real"
    if preset == "real":
        applied, kept = apply_real_scene_preset(config, all_methods.get(config.method_name))
        reason = "the scene is forward-facing" if config.scene_preset == "auto" else "--scene-preset real"
        notes.append(f"real-scene preset ({reason}): {', '.join(applied)}")
        if kept:
            notes.append(f"  kept your settings for: {', '.join(kept)}")
    config.scene_preset = preset
    effects = config.pipeline.effects.resolve(declared)
    config.pipeline.effects = EffectsConfig.of(effects)
    notes.append(f"scene effects: {effects.describe()} (the scene declares: {declared.describe()})")
    return config, notes


def resume_config(method_name: str, load_dir: Path) -> TrainerConfig:
    """The saved config of the run in ``load_dir``, set to resume there (it must be a ``method_name`` run)."""
    saved = load_config(load_dir, TrainerConfig, config_registry())
    if saved.method_name != method_name:
        fail(
            f"{load_dir} holds a '{saved.method_name}' run, but '{method_name}' was asked to resume it",
            f"run: fourierf-train {saved.method_name} --load-dir {load_dir}",
        )
    saved.load_dir = Path(load_dir)
    return saved
