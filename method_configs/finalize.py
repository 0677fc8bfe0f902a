"""From what a user typed to the finished config a ``Trainer`` takes, and back from a saved run.

Everything that depends on the scene is decided here, once, before anything is built: the scene's declared effects
combined with the user's overrides, and the synthetic or real-scene preset. The trainer, pipeline and model only
read the result, and ``config.json`` records it.
"""

from __future__ import annotations

import copy
from pathlib import Path

from fourierf_plugin.configs.base import config_classes, load_config, to_dict
from fourierf_plugin.data.parsers.capture_parser import CaptureParserConfig
from fourierf_plugin.data.scene_effects import EffectsConfig
from fourierf_plugin.engine.loading import check_same_scene, locate_data
from fourierf_plugin.engine.machine import pick_device
from fourierf_plugin.engine.option_checks import check_mlp_flags, check_saved_config, ignored_band_flags
from fourierf_plugin.engine.trainer import TrainerConfig
from fourierf_plugin.method_configs.budget import apply_budget_rule
from fourierf_plugin.method_configs.registry import all_methods
from fourierf_plugin.method_configs.scene_presets import apply_real_scene_preset, apply_settings
from fourierf_plugin.method_configs.sizing import run_size
from fourierf_plugin.method_configs.time_budget import apply_time_budget
from fourierf_plugin.utils.console import warn
from fourierf_plugin.utils.errors import fail


def config_registry() -> dict[str, type]:
    """Every config class a saved run may name: the built-in ones and those of installed plugins (importing this
    module imported them all)."""
    return config_classes()


def finalize(config: TrainerConfig, given: frozenset[str] = frozenset()) -> tuple[TrainerConfig, list[str]]:
    """A copy of ``config`` with ``--data`` in its parser, the scene preset applied and the scene's effects resolved;
    and the notes that say what was decided and why (for the caller to print). ``given``: the config paths of the
    flags the user typed (``given_options``), which no preset, sizing or rule overrides."""
    config = copy.deepcopy(config)
    check_mlp_flags(config, given)
    ignored = ignored_band_flags(config, given)
    if ignored:
        warn(
            f"{' '.join(ignored)} set the Fourier curriculum, which is off in this run ({config.method_name}): "
            "ignored; train a fourierf-* preset to use them"
        )
    parser = config.pipeline.datamanager.dataparser
    if config.data is not None and str(parser.data) != "." and Path(parser.data) != Path(config.data):
        fail(
            f"two scene folders given: --data {config.data} and, after the parser subcommand, --data {parser.data}",
            "pass --data once",
        )
    if config.data is not None:
        parser.data = config.data
    parser.data = Path(parser.data).expanduser().resolve()  # config.json must work from any working directory
    config.data = parser.data
    config.output_dir = Path(config.output_dir).expanduser().resolve()
    declared = parser.setup().declaration()
    notes = []
    if isinstance(parser, CaptureParserConfig):  # config.json records the decision, so a saved run keeps it
        parser.pin(declared)
    if declared.reason:
        notes.append(f"scene kind: {declared.kind_label} ({declared.reason})")
    preset = config.scene_preset
    if preset == "auto":
        preset = "synthetic" if declared.bounded else "real"
    if preset == "real":
        applied, kept = apply_real_scene_preset(config, all_methods.get(config.method_name), given)
        reason = "the scene is forward-facing" if config.scene_preset == "auto" else "--scene-preset real"
        notes.append(f"real-scene preset ({reason}): {', '.join(applied)}")
        if kept:
            notes.append(f"  kept your settings for: {', '.join(kept)}")
    config.scene_preset = preset
    reference = preset_under_scene(all_methods.get(config.method_name), preset)
    if config.time_budget is not None:  # the budget picks the count, as if typed, before the rules see it
        given = given | {"max_num_iterations"}
    notes += size_the_run(config, reference, not declared.bounded, given)

    def finish(run: TrainerConfig) -> list[str]:
        """The short-run rules, the TV decay and the scene's effects: what depends on the iteration count."""
        lines = apply_budget_rule(run, reference, given, declared.background)
        resolve_tv_decay(run)
        effects = run.pipeline.effects.resolve(declared)
        run.pipeline.effects = EffectsConfig.of(effects)
        return [*lines, f"scene effects: {effects.describe()} (the scene declares: {declared.describe()})"]

    notes += apply_time_budget(config, finish, declared.background)
    notes += finish(config)
    return config, notes


def preset_under_scene(pristine: TrainerConfig | None, preset: str) -> TrainerConfig | None:
    """The method preset as the scene preset leaves it: what "a value the user left alone" means to the rules applied
    after the scene preset (the real-scene preset's ramp is not a user's setting that the budget rule must keep)."""
    if pristine is None or preset != "real":
        return pristine
    reference = copy.deepcopy(pristine)
    apply_real_scene_preset(reference, None)
    return reference


def resolve_tv_decay(config: TrainerConfig) -> None:
    """TensoRF decays its TV weights by the lr's factor: an unset ``tv_decay_ratio`` becomes the optimiser's
    ``lr_decay_ratio`` here, once, so the model never reads the optimiser's config (a value the user gave stays)."""
    model = config.pipeline.model
    if model.tv_decay_ratio is None:
        model.tv_decay_ratio = config.optimizer.lr_decay_ratio


def size_the_run(
    config: TrainerConfig, pristine: TrainerConfig | None, forward_facing: bool, given: frozenset[str] = frozenset()
) -> list[str]:
    """Iterations, batch and grid from the training images, the device and the kind of scene (``sizing``), where the
    user left the preset's values; the note that says so."""
    train = config.pipeline.datamanager.dataparser.setup().get_outputs("train")
    views, height, width = train.images.shape[0], train.cameras.height, train.cameras.width
    size = run_size(views, height, width, pick_device(config.device), forward_facing)
    applied, kept = apply_settings(config, pristine, size.settings(), given)
    if config.time_budget is not None and "max_num_iterations" in kept:  # the budget's, said by its own note
        kept.remove("max_num_iterations")
    if not applied:
        return []
    note = f"run size for {size.reason}: {', '.join(applied)}"
    return [note + (f" (kept your {', '.join(kept)})" if kept else "")]


def resume_config(
    method_name: str, load_dir: Path, data: Path | None = None, machine: TrainerConfig | None = None
) -> TrainerConfig:
    """The saved config of the run in ``load_dir``, set to resume there (it must be a ``method_name`` run), reading
    its scene from ``data`` if given (a moved scene), on the threads and device ``machine`` asks for (if given)."""
    saved = load_config(load_dir, TrainerConfig, config_registry())
    check_saved_config(saved, Path(load_dir) / "config.json")
    if machine is not None:
        saved.threads = machine.threads if machine.threads is not None else saved.threads
        saved.device = machine.device if machine.device != "auto" else saved.device
    parser = saved.pipeline.datamanager.dataparser
    recorded = Path(parser.data)
    parser.data = locate_data(saved, Path(load_dir), data)
    if saved.method_name != method_name:
        fail(
            f"{load_dir} holds a '{saved.method_name}' run, but '{method_name}' was asked to resume it",
            f"run: fourierf-train {saved.method_name} --load-dir {load_dir}",
        )
    if data is not None and Path(parser.data) != recorded:  # config.json and views.json will name it from now on
        check_same_scene(Path(load_dir), Path(parser.data), parser.setup().get_outputs("train"))
    saved.load_dir = Path(load_dir)
    return saved


RESUME_FLAGS = frozenset({"load_dir", "data", "threads", "device"})
"""What a resume command may say: where the run is, where its scene moved, and what it runs on."""


def ignored_on_resume(config: TrainerConfig, given: frozenset[str] = frozenset()) -> list[str]:
    """The flags of a resume command that the saved run would silently ignore: every flag typed (``given``, the
    config paths of ``given_options``) and every value that differs from the method's preset, except
    ``--load-dir``, ``--data``, ``--threads`` and ``--device`` (a resumed run keeps its own config; those four say
    where it runs, and ``resume_config`` applies them). A typed value equal to the preset's counts too."""
    typed = {k for k in given if k not in RESUME_FLAGS}
    preset = all_methods.get(config.method_name)
    if preset is not None:
        values, default = _flat(to_dict(config)), _flat(to_dict(preset))
        typed |= {k for k, v in values.items() if k not in RESUME_FLAGS and default.get(k) != v}
    return sorted(f"--{k.replace('_', '-')}" for k in typed)


def _flat(tree: object, prefix: str = "") -> dict[str, object]:
    if not isinstance(tree, dict):
        return {prefix: tree}
    out: dict[str, object] = {}
    for key, value in tree.items():
        if key == "_type" and prefix:
            out[f"{prefix}._type"] = value
        elif key != "_type":
            out |= _flat(value, f"{prefix}.{key}" if prefix else key)
    return out
