"""The layer that finishes a config (``method_configs/finalize.py``, ``scene_presets.py``).

``finalize`` is where everything scene-dependent is decided, once, before anything is built: ``--data`` goes into
the parser, a forward-facing scene gets the real-scene preset (only where the user kept the method preset's value:
a flag given on the command line always wins), and the scene's effects are resolved and recorded in the config; its
notes say what was decided and why. ``resume_config`` hands back a saved run's config and refuses to resume it as
another method; ``config_registry`` must know every config class a saved run of the package can name.
"""

from __future__ import annotations

import copy
import dataclasses
import json
import subprocess
import sys
from pathlib import Path

import pytest

from fourierf_plugin.configs.base import InstantiateConfig, save_config, to_dict
from fourierf_plugin.data.parsers.blender import BLENDER_DECLARATION
from fourierf_plugin.data.parsers.llff import LLFF_DECLARATION, LLFFDataParserConfig
from fourierf_plugin.data.scene_effects import EffectsConfig, SceneEffects
from fourierf_plugin.engine.trainer import TrainerConfig
from fourierf_plugin.method_configs import all_methods, config_registry, finalize, resume_config
from fourierf_plugin.method_configs.budget import Run, rules_for, short_run_settings
from fourierf_plugin.method_configs.finalize import ignored_on_resume
from fourierf_plugin.method_configs.scene_presets import (
    REAL_SCENE_SETTINGS,
    VM_REAL_SCENE_SETTINGS,
    apply_real_scene_preset,
)
from fourierf_plugin.scripts.train import parse_args
from fourierf_plugin.utils.errors import UserError
from tests.helpers import TINY_SCENE

VM_REAL = REAL_SCENE_SETTINGS | VM_REAL_SCENE_SETTINGS


def _get(obj, path: str):
    for part in path.split("."):
        obj = getattr(obj, part)
    return obj


def raw(data: Path, *flags: str, method: str = "fourierf-vm") -> TrainerConfig:
    """What ``fourierf-train METHOD --data DATA FLAGS`` parses to, before ``finalize`` (LLFF scenes get their
    parser subcommand)."""
    parser = ["llff-data", "--num-views", "3"] if (data / "poses_bounds.npy").exists() else []
    return parse_args([method, "--data", str(data), *flags, *parser])


def without_decisions(config: TrainerConfig) -> dict:
    """The config as data, less what ``finalize`` decides (scene and output folders made absolute, preset name,
    effects, the run's size, the TV decay, the budget rule's values)."""
    data = to_dict(config)
    data.pop("max_num_iterations")
    data["pipeline"]["datamanager"].pop("rays_per_batch")
    data["pipeline"]["model"]["field"].pop("n_voxels_init")
    data["pipeline"]["model"]["field"].pop("n_voxels_final")
    data["pipeline"]["model"]["field"].pop("density_components")
    data["pipeline"]["model"]["field"].pop("appearance_components")
    for decided in ("tv_decay_ratio", "tv_weight_density", "tv_weight_appearance", "entropy_weight"):
        data["pipeline"]["model"].pop(decided)
    for decided in ("ramp_fraction", "f0_density", "f0_color"):
        data["pipeline"]["model"]["fourier"].pop(decided)
    data["optimizer"].pop("weight_decay")
    data["optimizer"].pop("lr_grids")
    data["optimizer"].pop("lr_decay_ratio")
    data["pipeline"]["datamanager"]["dataparser"].pop("data")
    data.pop("data")
    data.pop("output_dir")
    data["pipeline"].pop("effects")
    data.pop("scene_preset")
    return data


# -- finalize ---------------------------------------------------------------------------------------------------------


def test_blender_scene_keeps_the_synthetic_preset_and_gets_its_declared_effects() -> None:
    given = raw(TINY_SCENE)
    before = copy.deepcopy(given)
    config, notes = finalize(given)
    assert given == before, "finalize works on a copy"
    assert config.pipeline.datamanager.dataparser.data == TINY_SCENE, "--data is copied into the parser"
    assert config.scene_preset == "synthetic"
    assert without_decisions(config) == without_decisions(given), "a bounded scene changes no setting"
    # the budget rule trains an object with alpha on a random background (both methods)
    assert config.pipeline.effects == EffectsConfig.of(dataclasses.replace(BLENDER_DECLARATION, background="random"))
    assert notes[0].startswith("run size for 4 view(s) of 100x100 on cpu: ")
    fired = [rule.name for rule in rules_for(Run.of(config, "white"))]
    assert notes[1].startswith("short-run defaults: a run of 800 iterations")
    assert [n.strip().split(":")[0] for n in notes[2 : 2 + len(fired)]] == fired, "one line per row that fired"
    declared = "(the scene declares: background=white, rays=euclidean, view-dependent=no, occlusion-regularisation=no, "
    assert notes[-1] == (
        f"scene effects: background=random, rays=euclidean, view-dependent=no, occlusion-regularisation=no {declared}"
        "bounded)"
    )
    assert len(notes) == 3 + len(fired)
    shorter, _ = finalize(raw(TINY_SCENE, "--max-num-iterations", "400"))
    assert shorter.pipeline.effects == EffectsConfig.of(BLENDER_DECLARATION), "shorter runs keep the declared white"


def test_without_data_the_parsers_own_path_is_used() -> None:
    given = copy.deepcopy(all_methods["fourierf-vm"])
    given.pipeline.datamanager.dataparser.data = TINY_SCENE
    assert given.data is None
    config, _ = finalize(given)
    assert config.pipeline.datamanager.dataparser.data == TINY_SCENE
    assert config.pipeline.effects.is_resolved


def test_forward_facing_scene_gets_every_real_scene_setting(llff_scene: Path) -> None:
    config, notes = finalize(raw(llff_scene))
    assert config.scene_preset == "real"
    rule = short_run_settings(Run.of(config, LLFF_DECLARATION.background))  # where the short-run rows differ
    for path, value in VM_REAL.items():
        assert _get(config, path) == rule.get(path, value), path
    assert config.pipeline.datamanager.dataparser.data == llff_scene
    assert config.pipeline.effects == EffectsConfig.of(LLFF_DECLARATION)
    assert notes[0].startswith("real-scene preset (the scene is forward-facing): ")
    assert "f0_density=0.01" in notes[0] and "weight_decay=0.0" in notes[0]
    assert not any("kept your settings" in n for n in notes)
    assert notes[-1].startswith("scene effects: background=none, rays=ndc") and notes[-1].endswith("forward-facing)")


def test_the_users_flags_survive_the_real_scene_preset(llff_scene: Path) -> None:
    flags = ["--optimizer.weight-decay", "0.1", "--pipeline.model.fourier.f0-density", "0.05"]
    config, notes = finalize(raw(llff_scene, *flags))
    assert config.scene_preset == "real"
    assert config.optimizer.weight_decay == 0.1 and config.pipeline.model.fourier.f0_density == 0.05
    assert config.pipeline.model.fourier.f0_color == 0.01, "the settings the user did not touch are applied"
    assert "  kept your settings for: pipeline.model.fourier.f0_density, optimizer.weight_decay" in notes
    assert "weight_decay=" not in notes[0] and "f0_density=" not in notes[0]


def test_a_forced_synthetic_preset_on_a_forward_facing_scene_keeps_the_effects(llff_scene: Path) -> None:
    given = raw(llff_scene, "--scene-preset", "synthetic")
    config, notes = finalize(given)
    assert config.scene_preset == "synthetic"
    assert without_decisions(config) == without_decisions(given)
    assert config.pipeline.effects.effects().ray_space == "ndc", "the scene's effects do not depend on the preset"
    assert not any("preset" in n for n in notes)


def test_a_forced_real_preset_on_a_bounded_scene_says_it_was_asked_for() -> None:
    config, notes = finalize(raw(TINY_SCENE, "--scene-preset", "real"))
    assert config.scene_preset == "real" and config.pipeline.model.fourier.f0_density == 0.01
    assert notes[0].startswith("real-scene preset (--scene-preset real): ")
    assert config.pipeline.effects.effects().ray_space == "euclidean"


def test_effect_overrides_win_over_the_declaration_and_are_recorded(llff_scene: Path, tmp_path: Path) -> None:
    flags = ["--pipeline.effects.background", "white", "--pipeline.effects.occlusion-regularization", "False"]
    config, notes = finalize(raw(llff_scene, *flags))
    expected = SceneEffects(background="white", ray_space="ndc", view_dependent=False, occlusion_regularization=False)
    assert config.pipeline.effects == EffectsConfig.of(expected)
    assert "scene effects: background=white, rays=ndc, view-dependent=no, occlusion-regularisation=no " in notes[-1]
    assert "(the scene declares: background=none" in notes[-1]
    save_config(config, tmp_path / "config.json")
    recorded = json.loads((tmp_path / "config.json").read_text())["config"]["pipeline"]["effects"]
    assert {k: v for k, v in recorded.items() if k != "_type"} == {
        "background": "white", "ray_space": "ndc", "view_dependent": False, "occlusion_regularization": False
    }  # fmt: skip


def test_a_methods_own_effect_setting_wins_over_the_declaration() -> None:
    """``fourierf-vm-code`` ships a view-dependent decoder: its preset sets the effect, the scene declares none."""
    config, _ = finalize(raw(TINY_SCENE, method="fourierf-vm-code"))
    assert BLENDER_DECLARATION.view_dependent is False
    assert config.pipeline.effects.effects().view_dependent is True


@pytest.mark.parametrize(
    ("method", "flags", "expected"),
    [
        ("fourierf-vm-paper", [], 0.1),  # TensoRF's lr decay, so TensoRF's TV decay
        ("fourierf-vm", [], 1.0),  # a short run's budget rule: no lr decay, so no TV decay
        ("tensorf-vm", [], 1.0),  # objects: the same rule
        ("tensorf-vm", ["--budget-rule", "False"], 0.1),  # TensoRF's
        ("fourierf-vm-code", [], 1.0),  # the official code decays nothing
        ("fourierf-vm", ["--optimizer.lr-decay-ratio", "0.3"], 0.3),
        ("fourierf-vm", ["--pipeline.model.tv-decay-ratio", "0.5"], 0.5),  # the user's value wins
        ("fourierf-vm-code", ["--pipeline.model.tv-decay-ratio", "0.1"], 0.1),
    ],
)
def test_the_tv_decay_follows_the_optimisers_lr_decay_unless_given(method: str, flags: list, expected: float) -> None:
    given = raw(TINY_SCENE, *flags, method=method)
    if "--pipeline.model.tv-decay-ratio" not in flags:
        assert given.pipeline.model.tv_decay_ratio is None, "the preset leaves it to the optimiser's decay"
    config, _ = finalize(given)
    assert config.pipeline.model.tv_decay_ratio == expected


# -- resume_config ----------------------------------------------------------------------------------------------------


@pytest.fixture
def saved_run(tmp_path: Path) -> tuple[Path, TrainerConfig]:
    config, _ = finalize(raw(TINY_SCENE))
    run_dir = tmp_path / "run"
    run_dir.mkdir()
    save_config(config, run_dir / "config.json")
    return run_dir, config


def test_resume_config_returns_the_saved_config_set_to_resume_there(saved_run) -> None:
    run_dir, config = saved_run
    resumed = resume_config("fourierf-vm", run_dir)
    assert resumed.load_dir == run_dir
    resumed.load_dir = None
    assert resumed == config


def test_a_resume_may_say_where_it_runs_and_nothing_else(saved_run) -> None:
    """``--threads``/``--device`` apply to a resumed run; any other flag would be ignored, so it is named instead."""
    run_dir, _ = saved_run
    command = parse_args(["fourierf-vm", "--load-dir", str(run_dir), "--threads", "1", "--device", "cpu"])
    assert ignored_on_resume(command) == []
    resumed = resume_config("fourierf-vm", run_dir, machine=command)
    assert (resumed.threads, resumed.device) == (1, "cpu")
    longer = parse_args(["fourierf-vm", "--load-dir", str(run_dir), "--max-num-iterations", "99", "--seed", "3"])
    assert ignored_on_resume(longer) == ["--max-num-iterations", "--seed"]


def test_resume_config_refuses_another_method(saved_run) -> None:
    run_dir, _ = saved_run
    with pytest.raises(UserError, match="'fourierf-vm' run, but 'tensorf-vm' was asked to resume it") as info:
        resume_config("tensorf-vm", run_dir)
    assert info.value.fix == f"run: fourierf-train fourierf-vm --load-dir {run_dir}"


# -- config_registry --------------------------------------------------------------------------------------------------


def config_nodes(config) -> list:
    """Every dataclass instance in a config tree."""
    found = [config]
    for value in vars(config).values():
        if hasattr(value, "__dataclass_fields__"):
            found += config_nodes(value)
    return found


FRESH_REGISTRY = """
import importlib, json, pkgutil
from fourierf_plugin.method_configs import config_registry
fresh = sorted(config_registry())
import fourierf_plugin
from fourierf_plugin.configs.base import config_classes
for module in pkgutil.walk_packages(fourierf_plugin.__path__, "fourierf_plugin."):
    importlib.import_module(module.name)
defined = sorted(n for n, c in config_classes().items() if c.__module__.startswith("fourierf_plugin."))
print(json.dumps({"fresh": fresh, "defined": defined}))
"""


def test_config_registry_knows_every_built_in_config_class() -> None:
    """In a fresh interpreter that imported only ``method_configs``, the registry already holds every config class
    the package defines (found by then importing all of its modules), so loading a saved run never depends on what
    happened to be imported; and it maps each name in every method's tree to that very class."""
    out = subprocess.run([sys.executable, "-c", FRESH_REGISTRY], capture_output=True, text=True, check=True).stdout
    found = json.loads(out)
    fresh, defined = set(found["fresh"]), set(found["defined"])
    assert defined <= fresh, f"unknown to a fresh registry: {sorted(defined - fresh)}"
    assert {"TrainerConfig", "PipelineConfig", "FourieRFModelConfig", "LLFFDataParserConfig"} <= defined

    registry = config_registry()
    trees = [*all_methods.values(), LLFFDataParserConfig()]
    for node in (n for tree in trees for n in config_nodes(tree) if isinstance(n, InstantiateConfig)):
        assert registry[type(node).__name__] is type(node)


# -- the real-scene preset itself -------------------------------------------------------------------------------------


def test_real_preset_applies_every_setting_to_a_pristine_vm_config() -> None:
    pristine = all_methods["fourierf-vm"]
    config = copy.deepcopy(pristine)
    applied, kept = apply_real_scene_preset(config, pristine)
    assert kept == [] and len(applied) == len(VM_REAL)
    for path, value in VM_REAL.items():
        assert _get(config, path) == value, path
    assert config.pipeline.model.field.density_components == (16, 4, 4)
    assert config.pipeline.model.field.appearance_components == (48, 12, 12)
    assert pristine.pipeline.model.fourier.f0_density == 0.3, "the registered preset is untouched"


def test_real_preset_leaves_cp_component_counts() -> None:
    pristine = all_methods["fourierf-cp"]
    config = copy.deepcopy(pristine)
    applied, _ = apply_real_scene_preset(config, pristine)
    assert config.pipeline.model.field.density_components == (96, 96, 96)
    assert config.pipeline.model.field.appearance_components == (288, 288, 288)
    assert len(applied) == len(REAL_SCENE_SETTINGS)
    assert config.pipeline.model.fourier.f0_density == 0.01


def test_real_preset_without_a_pristine_applies_everything() -> None:
    config = copy.deepcopy(all_methods["fourierf-vm"])
    config.optimizer.weight_decay = 0.3
    applied, kept = apply_real_scene_preset(config, None)
    assert kept == [] and len(applied) == len(VM_REAL)
    assert config.optimizer.weight_decay == 0.0
