"""The budget rule (``method_configs/budget.py``): short runs get the val-chosen values, the paper's budget keeps the
paper's, a flag always wins, and ``fourierf-vm-paper`` is the paper's at any budget."""

from __future__ import annotations

from pathlib import Path

import pytest

from fourierf_plugin.fields.fourier_tensorf_field import FieldConfig
from fourierf_plugin.method_configs import all_methods, finalize
from fourierf_plugin.method_configs.budget import (
    OBJECT_COMPONENTS,
    OBJECT_COMPONENTS_FROM,
    OBJECT_ENTROPY_FROM,
    OBJECT_ENTROPY_WEIGHT,
    OBJECT_NARROW_BAND,
    OBJECT_NARROW_BAND_FROM,
    OBJECT_NARROW_BAND_UP_TO,
    OBJECT_RANDOM_BACKGROUND_FROM,
    OBJECT_TV_WEIGHT,
    PAPER_ITERATIONS,
    REAL_DENSITY_AXES,
    REAL_DENSITY_AXES_UP_TO,
    REAL_OCCUPANCY_FROM,
    REAL_OCCUPANCY_STEP,
    REAL_RAMP_ITERATIONS,
    REAL_REVIVE_AT_ONCE_ABOVE,
    REAL_SHORT_TV_UP_TO,
    REAL_SHORT_TV_WEIGHT,
    REAL_TV_WEIGHT,
    SHORT_RUN_SETTINGS,
    short_run_settings,
)
from fourierf_plugin.scripts.train import given_options, parse_args
from tests.helpers import TINY_SCENE


def finished(method: str, data: Path, *flags: str):
    parser = ["llff-data", "--num-views", "3"] if (data / "poses_bounds.npy").exists() else []
    args = [method, "--data", str(data), "--device", "cpu", *flags, *parser]
    config, notes = finalize(parse_args(args), given_options(args))
    return config, notes


def test_rule_is_a_function_of_the_iteration_count() -> None:
    tv = OBJECT_TV_WEIGHT
    short = {"optimizer.weight_decay": 0.0, "optimizer.lr_decay_ratio": 1.0, "optimizer.lr_grids": 0.04}
    short |= {"pipeline.model.tv_weight_density": tv, "pipeline.model.tv_weight_appearance": tv}
    assert short_run_settings("fourierf-vm", "synthetic", OBJECT_COMPONENTS_FROM - 1) == short, "TensoRF's counts"
    density, appearance = OBJECT_COMPONENTS
    short |= {
        "pipeline.model.field.density_components": (density,) * 3,
        "pipeline.model.field.appearance_components": (appearance,) * 3,
        "pipeline.model.entropy_weight": OBJECT_ENTROPY_WEIGHT,
    }
    random = {"pipeline.effects.background": "random"}
    assert short_run_settings("tensorf-vm", "synthetic", PAPER_ITERATIONS - 1) == short | random, "masks off"
    assert short_run_settings("fourierf-vm", "synthetic", PAPER_ITERATIONS - 1) == short | random, "the paper's band"
    band = {
        "pipeline.model.fourier.f0_density": OBJECT_NARROW_BAND,
        "pipeline.model.fourier.f0_color": OBJECT_NARROW_BAND,
    }
    assert short_run_settings("fourierf-vm", "synthetic", OBJECT_NARROW_BAND_UP_TO) == short | band | random
    assert short_run_settings("tensorf-vm", "synthetic", OBJECT_NARROW_BAND_UP_TO) == short | random, "no band to set"
    assert short_run_settings("fourierf-vm", "synthetic", OBJECT_NARROW_BAND_UP_TO + 1) == short | random
    assert OBJECT_RANDOM_BACKGROUND_FROM == OBJECT_COMPONENTS_FROM == OBJECT_ENTROPY_FROM == OBJECT_NARROW_BAND_FROM
    assert short_run_settings("fourierf-vm", "synthetic", 3000, "none") == short, "photos: no alpha, no random colour"
    assert short_run_settings("tensorf-vm", "synthetic", 3000, "none") == short
    assert short_run_settings("fourierf-vm", "synthetic", 3000, "black") == short, "scored on black: not measured"
    assert short_run_settings("fourierf-vm", "synthetic", PAPER_ITERATIONS) == {}
    real = {"optimizer.lr_grids": 0.08, "pipeline.model.tv_decay_ratio": 1.0}
    tv = REAL_SHORT_TV_WEIGHT
    real |= {"pipeline.model.tv_weight_density": tv, "pipeline.model.tv_weight_appearance": tv}
    real_800 = real | {"pipeline.model.occupancy_update_fractions": (0.25,)}
    axes = {"pipeline.model.fourier.density_axes": REAL_DENSITY_AXES}
    assert short_run_settings("fourierf-vm", "real", 800) == real_800 | axes, "the curriculum on the image plane"
    assert short_run_settings("tensorf-vm", "real", 800) == real_800, "forward-facing: the same rule, masks off"
    assert short_run_settings("fourierf-vm", "real", REAL_OCCUPANCY_FROM - 1) == real | axes, "the preset's 10 %"
    ramp = "pipeline.model.fourier.ramp_fraction"
    assert short_run_settings("fourierf-vm", "real", 3000)[ramp] == 0.2667, "the band opens by step 800"
    assert round(0.2667 * 3000) == REAL_RAMP_ITERATIONS
    assert ramp not in short_run_settings("tensorf-vm", "real", 3000), "no band to open"
    patience = "pipeline.model.field.revive_patience"
    for method in ("fourierf-vm", "tensorf-vm"):  # a longer forward-facing run revives a dark field at once
        assert short_run_settings(method, "real", REAL_REVIVE_AT_ONCE_ABOVE + 1)[patience] == 1
        assert patience not in short_run_settings(method, "real", REAL_REVIVE_AT_ONCE_ABOVE)
        assert patience not in short_run_settings(method, "synthetic", 3000), "objects: softplus, no ReLU to revive"
    # objects keep the paper's 20 % at any budget
    assert all(ramp not in short_run_settings("fourierf-vm", "synthetic", n) for n in (300, 800, 3000))
    assert short_run_settings("zerorf-vm", "real", 800) == {}
    # the table is not handed out for mutation
    short_run_settings("fourierf-vm", "real", 800)["optimizer.lr_grids"] = 1.0
    short_run_settings("tensorf-vm", "synthetic", 800)["optimizer.lr_grids"] = 1.0
    assert SHORT_RUN_SETTINGS[("fourierf-vm", "real")]["optimizer.lr_grids"] == 0.08
    assert SHORT_RUN_SETTINGS[("fourierf-vm", "synthetic")]["optimizer.lr_grids"] == 0.04


def test_cpu_run_of_an_object_drops_weight_decay_and_says_so() -> None:
    config, notes = finished("fourierf-vm", TINY_SCENE)
    assert config.max_num_iterations < PAPER_ITERATIONS
    assert config.optimizer.weight_decay == 0.0 and config.optimizer.lr_decay_ratio == 1.0
    assert config.pipeline.model.tv_decay_ratio == 1.0, "no lr decay: no TV decay either"
    assert config.optimizer.lr_grids == 0.04
    model = config.pipeline.model
    assert model.tv_weight_density == model.tv_weight_appearance == OBJECT_TV_WEIGHT
    preset_field = all_methods["fourierf-vm"].pipeline.model.field
    assert model.field.density_components == (OBJECT_COMPONENTS[0],) * 3 != preset_field.density_components
    assert model.field.appearance_components == (OBJECT_COMPONENTS[1],) * 3 != preset_field.appearance_components
    assert model.fourier.ramp_fraction == all_methods["fourierf-vm"].pipeline.model.fourier.ramp_fraction, "the paper's"
    assert any(n.startswith("budget rule") and "weight_decay=0.0" in n for n in notes)


def test_an_object_run_trains_on_a_random_background_from_a_band_that_follows_the_budget() -> None:
    config, notes = finished("fourierf-vm", TINY_SCENE)
    default = config.max_num_iterations  # the CPU default: where the band's and the background's rules start
    assert OBJECT_NARROW_BAND_FROM == OBJECT_RANDOM_BACKGROUND_FROM == default < OBJECT_NARROW_BAND_UP_TO
    model = config.pipeline.model
    paper = all_methods["fourierf-vm"].pipeline.model.fourier
    assert (paper.f0_density, paper.f0_color) == (0.3, 0.3)
    assert (model.fourier.f0_density, model.fourier.f0_color) == (OBJECT_NARROW_BAND,) * 2 != (0.3, 0.3)
    assert config.pipeline.effects.background == "random", "the scene declares white: its images carry alpha"
    assert model.random_background_from is None, "random from the step after the first occupancy update, white before"
    band = f"f0_density={OBJECT_NARROW_BAND}, f0_color={OBJECT_NARROW_BAND}"
    rule_note = f"{band}, background=random, entropy_weight={OBJECT_ENTROPY_WEIGHT};"  # the rule's last four, in order
    assert any(n.startswith("budget rule") and rule_note in n for n in notes)
    tensorf, _ = finished("tensorf-vm", TINY_SCENE)
    assert tensorf.pipeline.effects.background == "random", "the same background, masks off"
    longer, notes = finished("fourierf-vm", TINY_SCENE, "--max-num-iterations", str(OBJECT_NARROW_BAND_UP_TO + 1))
    assert (longer.pipeline.model.fourier.f0_density, longer.pipeline.model.fourier.f0_color) == (0.3, 0.3)
    assert longer.pipeline.effects.background == "random"
    assert not any("f0_density" in n for n in notes), "the narrow band lost at 1040 and 1500 iterations"
    for measured in (900, 1000):  # the narrow band won there on every seed (session 64)
        between, _ = finished("fourierf-vm", TINY_SCENE, "--max-num-iterations", str(measured))
        assert between.pipeline.model.fourier.f0_density == OBJECT_NARROW_BAND, f"{measured} iterations"
    short, _ = finished("fourierf-vm", TINY_SCENE, "--max-num-iterations", str(OBJECT_RANDOM_BACKGROUND_FROM - 1))
    assert short.pipeline.effects.background == "white"
    assert short.pipeline.model.fourier.f0_density == 0.3, "measured on the rest of the object rule, from 800 up"
    mine, notes = finished("fourierf-vm", TINY_SCENE, "--pipeline.model.fourier.f0-color", "0.3")
    assert (mine.pipeline.model.fourier.f0_density, mine.pipeline.model.fourier.f0_color) == (OBJECT_NARROW_BAND, 0.3)
    assert any("kept your pipeline.model.fourier.f0_color" in n for n in notes), (
        "a flag wins, one typed as the preset's"
    )


@pytest.mark.parametrize("method", ["fourierf-vm", "tensorf-vm"])
def test_an_object_run_scores_the_ray_entropy_and_a_shorter_one_does_not(method: str) -> None:
    config, notes = finished(method, TINY_SCENE)
    assert config.max_num_iterations >= OBJECT_ENTROPY_FROM
    assert all_methods[method].pipeline.model.entropy_weight == 0.0, "the preset has it off"
    assert config.pipeline.model.entropy_weight == OBJECT_ENTROPY_WEIGHT > 0
    assert any(n.startswith("budget rule") and f"entropy_weight={OBJECT_ENTROPY_WEIGHT}" in n for n in notes)
    short, _ = finished(method, TINY_SCENE, "--max-num-iterations", str(OBJECT_ENTROPY_FROM - 1))
    assert short.pipeline.model.entropy_weight == 0.0, "measured from 800 iterations up"
    mine, notes = finished(method, TINY_SCENE, "--pipeline.model.entropy-weight", "0")
    assert mine.pipeline.model.entropy_weight == 0.0, "a flag wins, also one that turns it off"
    assert any("kept your pipeline.model.entropy_weight" in n for n in notes)


@pytest.mark.parametrize("background", ["white", "black"])
def test_a_background_the_user_chose_is_kept(background: str) -> None:
    config, notes = finished("fourierf-vm", TINY_SCENE, "--pipeline.effects.background", background)
    assert config.pipeline.effects.background == background
    assert not any("background=random" in n for n in notes)
    rule = [n for n in notes if n.startswith("budget rule")]
    assert len(rule) == 1 and "kept your pipeline.effects.background" in rule[0], "the rest of the rule still applies"


def test_paper_budget_keeps_the_papers_values() -> None:
    config, notes = finished("fourierf-vm", TINY_SCENE, "--max-num-iterations", str(PAPER_ITERATIONS + 2000))
    assert config.optimizer.weight_decay == all_methods["fourierf-vm"].optimizer.weight_decay == 0.2
    assert not any(n.startswith("budget rule") for n in notes)


def test_a_flag_wins_over_the_rule() -> None:
    config, notes = finished("fourierf-vm", TINY_SCENE, "--optimizer.weight-decay", "0.05")
    assert config.optimizer.weight_decay == 0.05
    assert config.optimizer.lr_decay_ratio == 1.0, "the values the user did not touch still follow the rule"
    assert any(n.startswith("budget rule") and "kept your optimizer.weight_decay" in n for n in notes)


def test_a_flag_typed_with_the_presets_own_value_wins_too() -> None:
    """The config alone cannot tell ``--pipeline.model.field.density-components 16 16 16`` from the preset's default:
    the typed flags can."""
    preset = all_methods["fourierf-vm"]
    density = preset.pipeline.model.field.density_components
    flag = ["--pipeline.model.field.density-components", *map(str, density)]
    config, notes = finished("fourierf-vm", TINY_SCENE, *flag)
    assert config.pipeline.model.field.density_components == density
    assert config.pipeline.model.field.appearance_components == (OBJECT_COMPONENTS[1],) * 3, "the untyped one follows"
    assert any("kept your pipeline.model.field.density_components" in n for n in notes)
    # the paper's budget typed on a CPU: neither the run sizing nor the rule shortens or changes it
    flag = f"--max-num-iterations={preset.max_num_iterations}"
    config, notes = finished("fourierf-vm", TINY_SCENE, flag)
    assert config.max_num_iterations == preset.max_num_iterations == PAPER_ITERATIONS
    assert config.optimizer.weight_decay == preset.optimizer.weight_decay
    assert not any(n.startswith("budget rule") for n in notes)


def test_the_rule_can_be_turned_off() -> None:
    config, notes = finished("fourierf-vm", TINY_SCENE, "--budget-rule", "False")
    assert config.optimizer.weight_decay == 0.2
    assert not any(n.startswith("budget rule") for n in notes)


def test_paper_preset_keeps_the_papers_values_at_any_budget() -> None:
    config, notes = finished("fourierf-vm-paper", TINY_SCENE)
    assert config.max_num_iterations < PAPER_ITERATIONS
    assert config.optimizer.weight_decay == 0.2
    assert not any(n.startswith("budget rule") for n in notes)


@pytest.mark.parametrize("method", ["fourierf-vm", "tensorf-vm"])
def test_forward_facing_short_run_gets_the_faster_grid_rate_and_constant_tv(llff_scene: Path, method: str) -> None:
    config, _ = finished(method, llff_scene, "--max-num-iterations", "3000")
    assert config.scene_preset == "real"
    assert config.optimizer.lr_grids == 0.08
    model = config.pipeline.model
    assert model.tv_decay_ratio == 1.0 and model.tv_weight_density == model.tv_weight_appearance == REAL_TV_WEIGHT
    assert model.entropy_weight == 0.0, "the ray entropy lowered both methods on fern"
    long_run, _ = finished(method, llff_scene, "--max-num-iterations", str(PAPER_ITERATIONS + 2000))
    assert long_run.optimizer.lr_grids == 0.02
    assert long_run.pipeline.model.tv_weight_density == long_run.pipeline.model.tv_weight_appearance == 1.0


def test_a_longer_forward_facing_run_opens_the_band_by_step_800(llff_scene: Path) -> None:
    config, notes = finished("fourierf-vm", llff_scene, "--max-num-iterations", "3000")
    assert config.pipeline.model.fourier.ramp_fraction == 0.2667, "the real-scene preset's ramp is not a user's"
    assert any(n.startswith("budget rule") and "ramp_fraction=0.2667" in n for n in notes)
    mine, notes = finished(
        "fourierf-vm", llff_scene, "--max-num-iterations", "3000", "--pipeline.model.fourier.ramp-fraction", "0.5"
    )
    assert mine.pipeline.model.fourier.ramp_fraction == 0.5
    assert any("kept your pipeline.model.fourier.ramp_fraction" in n for n in notes)
    short, _ = finished("fourierf-vm", llff_scene, "--max-num-iterations", str(REAL_RAMP_ITERATIONS))
    assert short.pipeline.model.fourier.ramp_fraction == 1.0, "a short run keeps the whole-run ramp that won at 800"


@pytest.mark.parametrize("method", ["fourierf-vm", "tensorf-vm"])
def test_a_run_of_up_to_800_forward_facing_iterations_gets_the_stronger_tv(llff_scene: Path, method: str) -> None:
    tv = ("pipeline.model.tv_weight_density", "pipeline.model.tv_weight_appearance")
    assert REAL_SHORT_TV_WEIGHT > REAL_TV_WEIGHT and REAL_SHORT_TV_UP_TO == 800
    for iterations in (100, REAL_SHORT_TV_UP_TO):
        settings = short_run_settings(method, "real", iterations)
        assert [settings[path] for path in tv] == [REAL_SHORT_TV_WEIGHT] * 2, iterations
    longer = short_run_settings(method, "real", REAL_SHORT_TV_UP_TO + 1)
    assert [longer[path] for path in tv] == [REAL_TV_WEIGHT] * 2, "longer runs: TV 4"
    objects = short_run_settings(method, "synthetic", 800)
    assert [objects[path] for path in tv] == [OBJECT_TV_WEIGHT] * 2, "objects: their own rule"
    config, notes = finished(method, llff_scene, "--max-num-iterations", "800")
    model = config.pipeline.model
    assert model.tv_weight_density == model.tv_weight_appearance == REAL_SHORT_TV_WEIGHT
    assert model.tv_decay_ratio == 1.0
    assert any(n.startswith("budget rule") and f"tv_weight_density={REAL_SHORT_TV_WEIGHT}" in n for n in notes)
    mine, _ = finished(method, llff_scene, "--max-num-iterations", "800", "--pipeline.model.tv-weight-density", "4")
    assert mine.pipeline.model.tv_weight_density == 4.0, "a flag wins"
    assert mine.pipeline.model.tv_weight_appearance == REAL_SHORT_TV_WEIGHT, "the other weight follows the rule"


def test_a_short_forward_facing_run_filters_the_density_on_the_image_plane_only(llff_scene: Path) -> None:
    axes = "pipeline.model.fourier.density_axes"
    assert REAL_DENSITY_AXES == (0, 1), "x and y: NDC depth unfiltered"
    for iterations in (100, 800, REAL_DENSITY_AXES_UP_TO):
        assert short_run_settings("fourierf-vm", "real", iterations)[axes] == REAL_DENSITY_AXES, iterations
    assert axes not in short_run_settings("fourierf-vm", "real", REAL_DENSITY_AXES_UP_TO + 1), "longer runs: every axis"
    assert axes not in short_run_settings("tensorf-vm", "real", 800), "no band to filter"
    assert axes not in short_run_settings("fourierf-vm", "synthetic", 800), "objects: every axis"
    config, notes = finished("fourierf-vm", llff_scene, "--max-num-iterations", "800")
    assert config.pipeline.model.fourier.density_axes == REAL_DENSITY_AXES
    assert any(n.startswith("budget rule") and "density_axes=(0, 1)" in n for n in notes)
    mine, _ = finished(
        "fourierf-vm", llff_scene, "--max-num-iterations", "800", "--pipeline.model.fourier.density-axes", "0", "1", "2"
    )
    assert mine.pipeline.model.fourier.density_axes == (0, 1, 2), "a flag wins, even the preset's own value"
    paper, _ = finished("fourierf-vm-paper", llff_scene, "--max-num-iterations", "800")
    assert paper.pipeline.model.fourier.density_axes == (0, 1, 2)
    tensorf, _ = finished("tensorf-vm", llff_scene, "--max-num-iterations", "800")
    assert tensorf.pipeline.model.fourier.density_axes == (0, 1, 2)


def test_a_longer_forward_facing_run_revives_a_dark_density_field_at_once(llff_scene: Path) -> None:
    config, notes = finished("fourierf-vm", llff_scene, "--max-num-iterations", "3000")
    assert config.pipeline.model.field.revive_patience == 1
    assert any(n.startswith("budget rule") and "revive_patience=1" in n for n in notes)
    short, _ = finished("fourierf-vm", llff_scene, "--max-num-iterations", str(REAL_REVIVE_AT_ONCE_ABOVE))
    field_default = FieldConfig().revive_patience
    assert field_default > 1, "the field's default waits for a fresh field"
    assert short.pipeline.model.field.revive_patience == field_default, "at 800 iterations waiting won"
    mine, _ = finished(
        "fourierf-vm", llff_scene, "--max-num-iterations", "3000", "--pipeline.model.field.revive-patience", "4"
    )
    assert mine.pipeline.model.field.revive_patience == 4, "a flag wins"
    paper, _ = finished("fourierf-vm", llff_scene, "--max-num-iterations", str(PAPER_ITERATIONS))
    assert paper.pipeline.model.field.revive_patience == field_default


def test_a_forward_facing_runs_occupancy_update_waits_for_step_200(llff_scene: Path) -> None:
    occupancy = "pipeline.model.occupancy_update_fractions"
    for iterations in (REAL_OCCUPANCY_FROM, 1500, 1999):
        (fraction,) = short_run_settings("fourierf-vm", "real", iterations)[occupancy]
        assert round(fraction * iterations) == REAL_OCCUPANCY_STEP, iterations
    assert occupancy not in short_run_settings("fourierf-vm", "real", 2000), "10 % is step 200 already"
    assert occupancy not in short_run_settings("fourierf-vm", "synthetic", 800), "objects keep 20 % and 40 %"
    config, notes = finished("tensorf-vm", llff_scene, "--max-num-iterations", "800")
    assert config.pipeline.model.occupancy_update_fractions == (0.25,), "the real-scene preset's 10 % is not a user's"
    assert any(n.startswith("budget rule") and "occupancy_update_fractions=(0.25,)" in n for n in notes)
    mine, _ = finished(
        "fourierf-vm", llff_scene, "--max-num-iterations", "800", "--pipeline.model.occupancy-update-fractions", "0.1"
    )
    assert mine.pipeline.model.occupancy_update_fractions == (0.1,), "a flag wins, even the preset's own value"
    paper, _ = finished("fourierf-vm-paper", llff_scene, "--max-num-iterations", "800")
    assert paper.pipeline.model.occupancy_update_fractions == (0.1,)
