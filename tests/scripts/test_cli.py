"""The command line: presets, overrides, help text and the exit code 2 + clean message for every user mistake."""

from __future__ import annotations

import subprocess
from pathlib import Path

import pytest

from fourierf_plugin.configs.base import to_dict
from fourierf_plugin.engine.trainer import TrainerConfig
from fourierf_plugin.method_configs import all_descriptions, all_methods
from fourierf_plugin.scripts import eval as eval_script
from fourierf_plugin.scripts import train as train_script
from fourierf_plugin.scripts.cli import EXIT_USER_ERROR
from fourierf_plugin.scripts.train import build_config, given_options, parse_args
from tests.helpers import REPO_ROOT, TINY_SCENE, cli_exit_code, tiny_args, venv_script

PRESETS = ["fourierf-vm", "fourierf-cp", "fourierf-vm-code", "tensorf-vm", "tensorf-cp"]


# -- presets and overrides --------------------------------------------------------------------------------------
@pytest.mark.parametrize("method", PRESETS)
def test_every_preset_parses(method: str) -> None:
    config = parse_args([method])
    assert isinstance(config, TrainerConfig)
    assert config.method_name == method
    assert method in all_methods


def test_parsing_does_not_mutate_the_presets() -> None:
    before = to_dict(all_methods["fourierf-vm"])
    parse_args(["fourierf-vm", "--data", "elsewhere", "--pipeline.model.field.decomposition", "cp"])
    assert to_dict(all_methods["fourierf-vm"]) == before


def test_data_flag_lands_in_the_dataparser_when_the_config_is_finished() -> None:
    raw = parse_args(["fourierf-vm", "--data", str(TINY_SCENE)])
    assert raw.data == TINY_SCENE
    config, _ = build_config(raw)
    assert config.pipeline.datamanager.dataparser.data == TINY_SCENE


def test_blender_parser_subcommand_sets_its_fields() -> None:
    raw = parse_args(["fourierf-vm", "--data", str(TINY_SCENE), "blender-data", "--num-views", "4", "--downscale", "4"])
    parser = build_config(raw)[0].pipeline.datamanager.dataparser
    assert (parser.num_views, parser.downscale, parser.data) == (4, 4, TINY_SCENE)


def test_effect_flags_override_the_scene_and_the_rest_is_declared() -> None:
    """``--pipeline.effects.*`` sets what the user asked; finishing the config fills the rest from the scene."""
    raw = parse_args(["fourierf-vm", "--data", str(TINY_SCENE), "--pipeline.effects.background", "black",
                      "--pipeline.effects.view-dependent", "True"])  # fmt: skip
    assert (raw.pipeline.effects.background, raw.pipeline.effects.ray_space) == ("black", None)
    config, notes = build_config(raw)
    effects = config.pipeline.effects
    assert effects.is_resolved
    assert (effects.background, effects.view_dependent) == ("black", True)
    assert (effects.ray_space, effects.occlusion_regularization) == ("euclidean", False), "as the Blender scene says"
    assert any("background=black" in note for note in notes)


def test_accel_flags_land_in_the_model_accel_config() -> None:
    config = parse_args(["fourierf-vm", "--pipeline.model.accel.backend", "reference-grid-ops",
                         "--pipeline.model.accel.decoder-precision", "float32",
                         "--pipeline.model.accel.render-chunk-rays", "512"])  # fmt: skip
    accel = config.pipeline.model.accel
    assert (accel.backend, accel.decoder_precision, accel.render_chunk_rays) == ("reference-grid-ops", "float32", 512)
    assert parse_args(["fourierf-vm"]).pipeline.model.accel.backend == "accelerated"


@pytest.mark.parametrize(
    "old_flag",
    ["--pipeline.model.background", "--pipeline.model.view-dependent", "--pipeline.model.field.decoder-precision",
     "--pipeline.model.eval-chunk-rays"],
)  # fmt: skip
def test_flags_of_the_old_layout_are_refused(old_flag: str, capsys) -> None:
    with pytest.raises(SystemExit) as info:
        parse_args(["fourierf-vm", old_flag, "1"])
    assert info.value.code == 2
    assert old_flag in capsys.readouterr().err


def test_given_options_are_the_config_paths_of_the_typed_flags() -> None:
    args = ["fourierf-vm", "--optimizer.weight-decay=0.2", "--pipeline.model.field.density-components", "16", "16"]
    args += ["--max-num-iterations", "10000", "blender-data", "--downscale", "4", "-", "--"]
    assert given_options(args) == {
        "optimizer.weight_decay", "pipeline.model.field.density_components", "max_num_iterations", "downscale",
    }  # fmt: skip
    assert given_options(["fourierf-vm"]) == frozenset()


def test_cp_swap_on_the_vm_preset() -> None:
    assert parse_args(["fourierf-vm"]).pipeline.model.field.decomposition == "vm"
    config = parse_args(["fourierf-vm", "--pipeline.model.field.decomposition", "cp"])
    assert config.pipeline.model.field.decomposition == "cp"
    assert config.method_name == "fourierf-vm"


@pytest.mark.parametrize("decomposition", ["vm", "cp"])
def test_tensorf_preset_is_fourierf_with_the_masks_off(decomposition: str) -> None:
    fourierf = to_dict(parse_args([f"fourierf-{decomposition}"]))
    tensorf = to_dict(parse_args([f"tensorf-{decomposition}"]))
    assert fourierf["pipeline"]["model"]["fourier"]["enabled"] is True
    assert tensorf["pipeline"]["model"]["fourier"]["enabled"] is False
    assert fourierf["pipeline"]["model"]["field"]["decomposition"] == decomposition
    for tree in (fourierf, tensorf):
        del tree["method_name"]
        del tree["pipeline"]["model"]["fourier"]["enabled"]
    assert tensorf == fourierf


def test_help_lists_every_method_with_its_description(capsys, monkeypatch) -> None:
    monkeypatch.setenv("COLUMNS", "240")
    with pytest.raises(SystemExit) as info:
        parse_args(["--help"])
    assert info.value.code == 0
    # Flatten rich's box drawing and any wrapping so a description split across lines still matches.
    text = " ".join(capsys.readouterr().out.replace("│", " ").split())
    for method in PRESETS:
        assert method in text
        assert " ".join(all_descriptions[method].split()) in text, method


# -- user mistakes: exit code 2 and a message that says what to do ------------------------------------------------
def test_unknown_flag_exits_2(capsys) -> None:
    with pytest.raises(SystemExit) as info:
        parse_args(["fourierf-vm", "--no-such-flag", "3"])
    assert info.value.code == 2
    assert "--no-such-flag" in capsys.readouterr().err


def test_train_without_data_exits_2_and_asks_for_data(capsys) -> None:
    assert cli_exit_code(train_script.main, ["fourierf-vm"]) == EXIT_USER_ERROR
    err = capsys.readouterr().err
    assert "--data" in err
    assert "Traceback" not in err


def test_zero_iterations_exits_2(tmp_path: Path, capsys) -> None:
    args = tiny_args(tmp_path, iters=0)
    assert cli_exit_code(train_script.main, args) == EXIT_USER_ERROR
    err = capsys.readouterr().err
    assert "--max-num-iterations" in err
    assert "at least 1" in err
    assert not any(tmp_path.iterdir()), "a rejected run must not leave a run directory behind"


# The default event fractions (occupancy 0.2/0.4, upsample 0.3/0.7) cannot fit two iterations: the option checks
# refuse that before anything is built, naming the run length or the fraction flag.
def test_run_too_short_for_the_event_schedule_exits_2(tmp_path: Path, capsys) -> None:
    args = tiny_args(tmp_path, iters=2)
    assert cli_exit_code(train_script.main, args) == EXIT_USER_ERROR
    err = capsys.readouterr().err
    assert "--max-num-iterations" in err or "fractions" in err


def test_missing_scene_folder_exits_2_naming_it(tmp_path: Path, capsys) -> None:
    missing = tmp_path / "no_scene_here"
    args = tiny_args(tmp_path / "out", iters=10)
    args[args.index(str(TINY_SCENE))] = str(missing)
    assert cli_exit_code(train_script.main, args) == EXIT_USER_ERROR
    err = capsys.readouterr().err
    assert str(missing) in err
    assert "Traceback" not in err


def test_eval_of_a_missing_config_exits_2_in_process(tmp_path: Path, capsys) -> None:
    missing = tmp_path / "missing.json"
    code = cli_exit_code(eval_script.main, ["--load-config", str(missing), "--output-path", str(tmp_path / "x.json")])
    assert code == EXIT_USER_ERROR
    err = capsys.readouterr().err
    assert str(missing) in err
    assert "Traceback" not in err


def test_installed_eval_script_reports_a_missing_config_cleanly(tmp_path: Path) -> None:
    """The real console script: exit status 2, the path named, no Python traceback."""
    script = venv_script("fourierf-eval")
    if not script.exists():
        pytest.skip(f"{script} is not installed (pip install -e . first)")
    missing = tmp_path / "missing.json"
    proc = subprocess.run(
        [str(script), "--load-config", str(missing), "--output-path", str(tmp_path / "x.json")],
        capture_output=True,
        text=True,
        timeout=120,
        cwd=REPO_ROOT,
        env={"PATH": "/usr/bin:/bin", "COLUMNS": "200"},
    )
    assert proc.returncode == EXIT_USER_ERROR, proc.stderr
    assert str(missing) in proc.stderr
    assert "Traceback" not in proc.stderr
    assert not (tmp_path / "x.json").exists()
