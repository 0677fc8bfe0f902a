"""The short-run defaults (``method_configs/budget.py``): invariants of the table and of how finalize applies it, not
its tuned values (docs/defaults.md holds those and their evidence)."""

from __future__ import annotations

import copy
import itertools
import re
from dataclasses import replace
from pathlib import Path

import pytest

from fourierf_plugin.method_configs import all_methods, finalize
from fourierf_plugin.method_configs.budget import (
    FORWARD_FACING,
    OBJECT,
    PAPER_ITERATIONS,
    RULES,
    TRAINED_FIELDS,
    AtStep,
    Rule,
    Run,
    rule_span,
    rules_for,
)
from fourierf_plugin.method_configs.presets import descriptions
from fourierf_plugin.scripts.train import given_options, parse_args
from tests.helpers import TINY_SCENE

HEADER = "short-run defaults: "
BOUNDS = sorted({n for rule in RULES for lo, hi in [rule.iterations] for n in (lo, hi - 1, hi) if n > 0} | {1})
"""Every iteration count where some row starts or ends, and either side of it."""
FIELDS = (*TRAINED_FIELDS, "generated")
BACKGROUNDS = ("white", "black", "none")
VM_ONLY = {rule.name for rule in RULES if "cp" not in rule.fields}


def every_run() -> list[Run]:
    """Every combination of the properties a row can match on, at every boundary of the table."""
    kinds = itertools.product((OBJECT, FORWARD_FACING), (True, False), FIELDS, BOUNDS, BACKGROUNDS)
    return [Run(scene, curriculum, field, n, background) for scene, curriculum, field, n, background in kinds]


def finished(method: str, data: Path, *flags: str):
    parser = ["llff-data", "--num-views", "3"] if (data / "poses_bounds.npy").exists() else []
    args = [method, "--data", str(data), "--device", "cpu", *flags, *parser]
    return finalize(parse_args(args), given_options(args))


def get(obj, path: str):
    for part in path.split("."):
        obj = getattr(obj, part)
    return obj


def rule_lines(notes: list[str]) -> dict[str, str]:
    """The printed rows: name -> what the line says it set."""
    if not any(n.startswith(HEADER) for n in notes):
        return {}
    start = next(i for i, n in enumerate(notes) if n.startswith(HEADER)) + 1
    lines = itertools.takewhile(lambda n: n.startswith("  ") and ": " in n, notes[start:])
    return dict(line.strip().split(": ", 1) for line in lines)


# -- the table --------------------------------------------------------------------------------------------------------


def test_each_row_is_named_for_its_anchor_and_gives_a_one_line_reason() -> None:
    names = [rule.name for rule in RULES]
    assert len(set(names)) == len(names)
    for rule in RULES:
        assert re.fullmatch(r"[a-z0-9]+(-[a-z0-9]+)*", rule.name), "a slug: the name is its anchor in the record"
        assert rule.anchor == f"docs/defaults.md#{rule.name}"
        assert rule.reason and "\n" not in rule.reason
        assert rule.scene in (OBJECT, FORWARD_FACING)
        assert rule.settings, rule.name
        assert set(rule.fields) <= set(TRAINED_FIELDS), "a generated field keeps its published settings"


def test_ranges_are_half_open_and_short_of_the_papers_budget() -> None:
    for rule in RULES:
        lo, hi = rule.iterations
        assert isinstance(lo, int) and isinstance(hi, int)
        assert 0 <= lo < hi <= PAPER_ITERATIONS, rule.name
        run = Run(rule.scene, True, "vm", lo, "white")
        assert rule.applies(run) or rule.curriculum is False or rule.background not in (None, "white")
        bare = Rule(rule.name, rule.scene, rule.iterations, {}, "")
        assert not bare.applies(Run(rule.scene, True, "vm", hi, "white")), "the upper end is not in the range"


def test_no_two_rows_set_one_field_for_overlapping_runs() -> None:
    for run in every_run():
        seen: dict[str, str] = {}
        for rule in rules_for(run):
            for path in rule.settings:
                assert path not in seen, f"{path}: {seen.get(path)} and {rule.name} both apply to {run}"
                seen[path] = rule.name


def test_every_setting_is_a_field_of_the_presets_it_applies_to() -> None:
    preset = all_methods["fourierf-vm"]
    for rule in RULES:
        for path in rule.settings:
            get(preset, path)  # raises where the path names no field


def test_a_span_holds_the_same_rows_and_ends_where_they_change() -> None:
    for run in every_run():
        low, high = rule_span(run)
        assert low <= run.iterations < high
        names = [rule.name for rule in rules_for(run)]
        inside = {low, run.iterations, high - 1} if high < PAPER_ITERATIONS * 10 else {low, run.iterations}
        assert all([r.name for r in rules_for(replace(run, iterations=n))] == names for n in inside)
        if low > 0:
            assert [r.name for r in rules_for(replace(run, iterations=low - 1))] != names
        if high < PAPER_ITERATIONS * 10:
            assert [r.name for r in rules_for(replace(run, iterations=high))] != names


def test_a_fraction_at_a_step_lands_on_that_step_at_every_length() -> None:
    for rule in RULES:
        lo, hi = rule.iterations
        for path, value in rule.settings.items():
            steps = [v for v in (value if isinstance(value, tuple) else (value,)) if isinstance(v, AtStep)]
            for step, iterations in itertools.product(steps, range(max(lo, 1), hi, 7)):
                assert round(step.fraction(iterations) * iterations) == step.step, (rule.name, path, iterations)


def test_a_row_matches_by_properties() -> None:
    rule = Rule("r", OBJECT, (10, 20), {"seed": 1}, "why", curriculum=True, fields=("vm",), background="white")
    run = Run(OBJECT, True, "vm", 10, "white")
    assert rule.applies(run)
    assert not rule.applies(Run(FORWARD_FACING, True, "vm", 10, "white"))
    assert not rule.applies(Run(OBJECT, False, "vm", 10, "white"))
    assert not rule.applies(Run(OBJECT, True, "cp", 10, "white"))
    assert not rule.applies(Run(OBJECT, True, "vm", 10, "none"))
    assert not rule.applies(Run(OBJECT, True, "vm", 9, "white"))
    assert not rule.applies(Run(OBJECT, True, "vm", 20, "white"))
    with pytest.raises(TypeError):
        rule.settings["seed"] = 2  # type: ignore[index]


def test_cp_gets_every_row_vm_gets_but_those_about_the_vm_factors() -> None:
    """The curriculum's rows are the CP field's too; the rows left to VM say why in their reason."""
    assert VM_ONLY, "the component counts and the plane TV weights are VM's"
    for name in VM_ONLY:
        assert "VM only" in next(rule.reason for rule in RULES if rule.name == name)
    for run in every_run():
        if run.field != "vm":
            continue
        vm = {rule.name for rule in rules_for(run)}
        cp = {rule.name for rule in rules_for(Run(run.scene, run.curriculum, "cp", run.iterations, run.background))}
        assert cp <= vm and vm - cp <= VM_ONLY, run
        assert not rules_for(Run(run.scene, run.curriculum, "generated", run.iterations, run.background))


# -- applied by finalize ----------------------------------------------------------------------------------------------

METHODS = tuple(descriptions)
"""Every built-in preset."""
ITERATIONS = [None, 100, 801, 1001, 3000]
"""None: the run's size decides (on a CPU, the CPU default)."""


@pytest.fixture(params=["object", "forward-facing"])
def scene(request: pytest.FixtureRequest, llff_scene: Path) -> Path:
    return TINY_SCENE if request.param == "object" else llff_scene


def runs(scene: Path, *flags: str):
    """(method, finished config, notes, run) for every built-in preset at several lengths."""
    for method, iterations in itertools.product(METHODS, ITERATIONS):
        length = () if iterations is None else ("--max-num-iterations", str(iterations))
        config, notes = finished(method, scene, *length, *flags)
        background = "none" if (scene / "poses_bounds.npy").exists() else "white"
        yield method, config, notes, Run.of(config, background)


def test_the_printed_lines_are_the_rows_that_fired_and_what_they_set(scene: Path) -> None:
    for method, config, notes, run in runs(scene):
        printed = rule_lines(notes)
        fired = rules_for(run) if config.budget_rule else []
        assert list(printed) == [rule.name for rule in fired], (method, run)
        for rule in fired:
            values = rule.values(run.iterations)
            assert printed[rule.name] == ", ".join(f"{p.rsplit('.', 1)[-1]}={v}" for p, v in values.items())
            for path, value in values.items():
                assert get(config, path) == value, (method, rule.name, path)
        if fired:
            header = next(n for n in notes if n.startswith(HEADER))
            assert "departs from the paper's configuration" in header
            assert "--budget-rule False" in header and "fourierf-vm-paper" in header


def test_rows_never_fire_for_the_paper_presets_the_papers_budget_or_with_the_rule_off(scene: Path) -> None:
    for method, _, notes, _ in runs(scene):
        if method in ("fourierf-vm-paper", "fourierf-vm-code", "zerorf-vm"):
            assert not rule_lines(notes) and not any(n.startswith(HEADER) for n in notes), method
    for method in METHODS:
        _, notes = finished(method, scene, "--max-num-iterations", str(PAPER_ITERATIONS))
        assert not any(n.startswith(HEADER) for n in notes), method
    for method, _, notes, _ in runs(scene, "--budget-rule", "False"):
        assert not any(n.startswith(HEADER) for n in notes), method


def test_a_typed_flag_always_wins(scene: Path) -> None:
    """With every path a row sets typed, the rows change nothing and the run is not said to depart from the paper's."""
    every_path = frozenset(path for rule in RULES for path in rule.settings)
    for method in ("fourierf-vm", "tensorf-vm", "fourierf-cp"):
        for length in ((), ("--max-num-iterations", "1000"), ("--max-num-iterations", "3000")):
            command = parse_args([method, "--data", str(scene), "--device", "cpu", *length, *llff_flags(scene)])
            config, notes = finalize(command, given_options(length) | every_path)
            off = copy.deepcopy(command)
            off.budget_rule = False
            reference, _ = finalize(off, given_options(length) | every_path)
            reference.budget_rule = True
            assert config == reference, (method, length)
            assert not any(n.startswith(HEADER) for n in notes)


def test_a_flag_typed_with_the_presets_own_value_wins_too() -> None:
    """The config alone cannot tell ``--pipeline.model.field.density-components 16 16 16`` from the preset's default:
    the typed flags can; the rows' other values still apply."""
    density = all_methods["fourierf-vm"].pipeline.model.field.density_components
    config, notes = finished("fourierf-vm", TINY_SCENE, "--pipeline.model.field.density-components", *map(str, density))
    assert config.pipeline.model.field.density_components == density
    line = rule_lines(notes)["object-components"]
    assert "appearance_components=" in line and "kept your pipeline.model.field.density_components" in line


def test_the_papers_budget_typed_on_a_cpu_keeps_the_papers_values() -> None:
    preset = all_methods["fourierf-vm"]
    config, notes = finished("fourierf-vm", TINY_SCENE, f"--max-num-iterations={preset.max_num_iterations}")
    assert config.max_num_iterations == preset.max_num_iterations == PAPER_ITERATIONS
    assert config.optimizer == preset.optimizer
    assert not any(n.startswith(HEADER) for n in notes)


@pytest.mark.parametrize("background", ["white", "black"])
def test_a_background_the_user_chose_is_kept(background: str) -> None:
    config, notes = finished("fourierf-vm", TINY_SCENE, "--pipeline.effects.background", background)
    assert config.pipeline.effects.background == background
    assert "kept your pipeline.effects.background" in rule_lines(notes)["object-random-background"]


def llff_flags(scene: Path) -> list[str]:
    return ["llff-data", "--num-views", "3"] if (scene / "poses_bounds.npy").exists() else []
