"""config.json: an exact, data-only round trip, and one clear UserError for every way a file can be wrong.

Loading takes the registry of config classes a saved run may name (``method_configs.config_registry()``): a name
outside it is refused, so a hand-edited or corrupted file can neither build an arbitrary class nor be silently
read as something else. Files of another config format (format 1 kept the scene effects on the model) are refused
with a message that says which format the file has and which one this version reads.
"""

from __future__ import annotations

import copy
import json
from pathlib import Path

import pytest

from fourierf_plugin.configs.base import CONFIG_FORMAT, from_dict, load_config, save_config, to_dict
from fourierf_plugin.engine.trainer import TrainerConfig
from fourierf_plugin.method_configs import all_methods, config_registry
from fourierf_plugin.scripts.train import parse_args
from fourierf_plugin.utils.errors import UserError

PRESETS = ["fourierf-vm", "fourierf-cp", "fourierf-vm-code", "tensorf-vm", "tensorf-cp"]


def _overridden() -> TrainerConfig:
    """A config whose every kind of field (Path, tuples, Optional, Literal, nested) differs from a default."""
    return parse_args(
        [
            "fourierf-cp",
            "--data",
            "scenes/lego",
            "--seed",
            "7",
            "--threads",
            "1",
            "--timestamp",
            "t0",
            "--pipeline.effects.background",
            "black",
            "--pipeline.effects.view-dependent",
            "True",
            "--pipeline.model.accel.backend",
            "reference-grid-ops",
            "--pipeline.model.occupancy-update-fractions",
            "0.25",
            "0.5",
            "0.75",
            "--pipeline.model.field.density-components",
            "8",
            "8",
            "8",
            "--optimizer.betas",
            "0.8",
            "0.9",
            "blender-data",
            "--view-ids",
            "27",
            "76",
            "--downscale",
            "4",
        ]
    )


@pytest.mark.parametrize("method", PRESETS)
def test_every_preset_survives_a_json_round_trip(method: str) -> None:
    config = parse_args([method])
    again = from_dict(json.loads(json.dumps(to_dict(config))), TrainerConfig)
    assert again == config
    assert again == all_methods[method]


def test_overridden_fields_survive_a_json_round_trip() -> None:
    config = _overridden()
    again = from_dict(json.loads(json.dumps(to_dict(config))), TrainerConfig)
    assert again == config
    # Types come back as declared, not as JSON's lists and strings.
    assert isinstance(again.pipeline.datamanager.dataparser.data, Path)
    assert again.pipeline.datamanager.dataparser.view_ids == (27, 76)
    assert again.pipeline.model.field.density_components == (8, 8, 8)
    assert again.optimizer.betas == (0.8, 0.9)
    assert again.pipeline.effects.background == "black"
    assert again.pipeline.effects.ray_space is None, "an effect left as declared stays None"
    assert again.pipeline.model.accel.backend == "reference-grid-ops"


def test_save_and_load_config_round_trip(tmp_path: Path) -> None:
    config = _overridden()
    path = tmp_path / "config.json"
    save_config(config, path)
    payload = json.loads(path.read_text())
    assert payload["config_format"] == CONFIG_FORMAT
    assert payload["config"]["_type"] == "TrainerConfig"
    registry = config_registry()
    assert load_config(path, TrainerConfig, registry) == config
    assert load_config(tmp_path, TrainerConfig, registry) == config, "a run directory resolves to its config.json"
    assert not list(tmp_path.glob("*.tmp")), "the atomic write leaves no temp file"


def test_the_new_optimiser_and_tv_fields_round_trip_and_old_configs_without_them_load(tmp_path: Path) -> None:
    """``betas_after_reset`` and ``tv_decay_ratio`` come back as written; a config.json saved before they existed
    loads with both None, i.e. as that run trained (one set of betas, no TV decay)."""
    config = copy.deepcopy(all_methods["fourierf-vm-code"])
    config.pipeline.model.tv_decay_ratio = 0.25
    save_config(config, tmp_path / "config.json")
    again = load_config(tmp_path, TrainerConfig, config_registry())
    assert again.optimizer.betas_after_reset == (0.9, 0.98) and again.pipeline.model.tv_decay_ratio == 0.25
    old = json.loads((tmp_path / "config.json").read_text())
    del old["config"]["optimizer"]["betas_after_reset"], old["config"]["pipeline"]["model"]["tv_decay_ratio"]
    legacy = load_config(_write(tmp_path, old), TrainerConfig, config_registry())
    assert legacy.optimizer.betas_after_reset is None and legacy.pipeline.model.tv_decay_ratio is None
    assert legacy.optimizer.betas == (0.9, 0.99)


# -- every defect is one UserError that names the file ----------------------------------------------------------
def _saved_payload() -> dict:
    return {"fourierf_version": "0.1.0", "config_format": CONFIG_FORMAT, "config": to_dict(all_methods["fourierf-vm"])}


def _write(tmp_path: Path, payload: object) -> Path:
    path = tmp_path / "config.json"
    path.write_text(payload if isinstance(payload, str) else json.dumps(payload))
    return path


def _load_error(path: Path, registry: dict[str, type] | None = None) -> UserError:
    with pytest.raises(UserError) as info:
        load_config(path, TrainerConfig, config_registry() if registry is None else registry)
    err = info.value
    assert str(path) in err.problem, "the message names the file"
    assert err.fix, "the error says what to do"
    return err


def test_missing_file(tmp_path: Path) -> None:
    err = _load_error(tmp_path / "nope.json")
    assert "not found" in err.problem


def test_malformed_json(tmp_path: Path) -> None:
    err = _load_error(_write(tmp_path, '{"config": {'))
    assert "JSON" in err.problem


@pytest.mark.parametrize("payload", [{"fourierf_version": "0.1.0", "config_format": 1}, [1, 2], "3"])
def test_json_without_a_config(tmp_path: Path, payload: object) -> None:
    err = _load_error(_write(tmp_path, json.dumps(payload)))
    assert "config" in err.problem


@pytest.mark.parametrize("fmt", [CONFIG_FORMAT + 1, 0, None, "1"])
def test_another_config_format(tmp_path: Path, fmt: object) -> None:
    payload = _saved_payload()
    payload["config_format"] = fmt
    err = _load_error(_write(tmp_path, payload))
    assert "format" in err.problem


def test_a_format_1_config_is_refused_clearly(tmp_path: Path) -> None:
    """Format 1 (before the redesign) kept the scene effects on the model; such a file is refused by its format,
    before its fields are read, with the file's format, the format this version reads, and what to do."""
    payload = _saved_payload()
    payload["config_format"] = 1
    payload["fourierf_version"] = "0.0.9"
    model = payload["config"]["pipeline"]["model"]
    model["background"] = "white"  # where format 1 kept the effects
    del payload["config"]["pipeline"]["effects"]
    err = _load_error(_write(tmp_path, payload))
    assert "config format 1" in err.problem
    assert "0.0.9" in err.problem, "the message names the version that wrote the file"
    assert f"reads format {CONFIG_FORMAT}" in err.problem
    assert "background" not in err.problem, "refused by its format, not by the first field that no longer fits"
    assert "retrain" in err.fix


def _set(tree: dict, dotted: str, value: object) -> None:
    *parents, last = dotted.split(".")
    for key in parents:
        tree = tree[key]
    tree[last] = value


# An unknown name is refused wherever it stands: where the field's type is known (the top, pipeline.model) as well as
# in a union (the dataparser); it is never replaced by the declared type.
@pytest.mark.parametrize("where", ["_type", "pipeline.model._type", "pipeline.datamanager.dataparser._type"])
def test_unknown_class_name_is_rejected(tmp_path: Path, where: str) -> None:
    payload = _saved_payload()
    _set(payload["config"], where, "os.system")
    err = _load_error(_write(tmp_path, payload))
    assert "os.system" in err.problem


@pytest.mark.parametrize("missing", ["BlenderDataParserConfig", "LLFFDataParserConfig"])
def test_a_class_outside_the_given_registry_is_refused(tmp_path: Path, missing: str) -> None:
    """The registry passed in lists what a file may name where the field admits several classes (the dataparser):
    a real config class left out of it is refused like any unknown name, never looked up elsewhere."""
    payload = _saved_payload()
    payload["config"]["pipeline"]["datamanager"]["dataparser"] = {"_type": missing}  # its defaults
    path = _write(tmp_path, payload)
    registry = config_registry()
    assert isinstance(load_config(path, TrainerConfig, registry), TrainerConfig), "the full registry reads it"
    err = _load_error(path, {name: cls for name, cls in registry.items() if name != missing})
    assert missing in err.problem


# A registered class that is not the field's declared type is refused too (it would fail far from the file).
def test_registered_class_of_the_wrong_type_is_rejected(tmp_path: Path) -> None:
    payload = _saved_payload()
    payload["config"]["pipeline"]["model"] = {"_type": "InstantiateConfig"}
    _load_error(_write(tmp_path, payload))


@pytest.mark.parametrize(
    ("where", "value"),
    [
        ("max_num_iterations", "ten"),
        ("max_num_iterations", 1.5),
        ("max_num_iterations", True),
        ("seed", None),
        ("pipeline.model.tv_weight_density", "1.0"),
        ("pipeline.model.field.decomposition", "tucker"),
        ("pipeline.model.field.density_components", [16, 16, "16"]),
        ("pipeline.datamanager.dataparser.data", 3),
        ("pipeline.model.fourier", 1),
        ("pipeline.effects.background", "grey"),
        ("pipeline.model.accel.backend", "fast"),
    ],
)
def test_wrong_field_type(tmp_path: Path, where: str, value: object) -> None:
    payload = _saved_payload()
    _set(payload["config"], where, value)
    err = _load_error(_write(tmp_path, payload))
    assert where.rsplit(".", 1)[-1] in err.problem, "the message names the offending field"


def test_tuple_of_the_wrong_length_names_the_field(tmp_path: Path) -> None:
    payload = _saved_payload()
    _set(payload["config"], "pipeline.model.field.density_components", [16, 16])
    err = _load_error(_write(tmp_path, payload))
    assert "density_components" in err.problem


@pytest.mark.parametrize("where", ["bogus", "pipeline.model.field.bogus"])
def test_unknown_field(tmp_path: Path, where: str) -> None:
    payload = _saved_payload()
    _set(payload["config"], where, 1)
    err = _load_error(_write(tmp_path, payload))
    assert "bogus" in err.problem
