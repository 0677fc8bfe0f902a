"""The equal-iterations stage without training: a point's command (an iteration budget, a variant's flags), its row
from a faked run, and the report's tables and derived gaps from made-up rows."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import harness
import pytest
import report as rep

from tests.benchmarks.test_equal_time import fake_runs, point_command  # noqa: F401 (a fixture)
from tests.helpers import load_benchmark

runner = load_benchmark("run")

SUITE = harness.load_suite()
SCRIPT = Path(__file__).resolve().parents[2] / "benchmarks" / "run.py"
BUDGET = SUITE.equal_time["iterations"]["budget"]
SIZE_FLAGS = ("--time-budget", "n-voxels", "rays-per-batch")


def _row(scene: str, method: str, psnr: float, iterations: int = 800) -> dict:
    return {
        "key": f"{scene}/{method}/{iterations}it", "scene": scene, "method": method, "budget": f"{iterations}it",
        "budget_iterations": iterations, "iterations": iterations, "trained_seconds": iterations / 2,
        "seconds_per_iteration": 0.5,
        "psnr": psnr, "ssim": 0.8, "lpips": 0.2, "machine": "cpu, 2 cores", "jobs": 2, "seconds": 450.0,
    }  # fmt: skip


ROWS = [
    _row("lego", "fourierf-vm-paper", 21.5),
    _row("lego", "tensorf-vm-published", 19.25),
    _row("lego", "zerorf-vm", 20.0, 150),
    _row("lego", "zerorf-vm-no-alpha", 18.75, 150),
    _row("fern", "fourierf-vm-paper", 18.0),
    _row("fern", "tensorf-vm-published", 18.5),
]


def test_an_iteration_budget_is_max_iterations_with_no_size_flag(tmp_path: Path) -> None:
    cmd = point_command(runner.TimedPoint("fern", "tensorf-vm", BUDGET), tmp_path, tmp_path / "w")
    assert cmd[1] == "tensorf-vm" and cmd[cmd.index("--max-num-iterations") + 1] == BUDGET.removesuffix("it")
    assert not any(flag in c for c in cmd for flag in SIZE_FLAGS) and cmd[cmd.index("--threads") + 1] == "1"
    assert "--pipeline.model.alpha-weight" not in cmd
    assert runner.budget_iterations("800it") == 800
    assert runner.budget_iterations("3m") is runner.budget_iterations("0it") is None


def test_a_variant_trains_its_method_with_its_flags_under_its_own_key(tmp_path: Path) -> None:
    variant, plain = (runner.TimedPoint("lego", m, BUDGET) for m in ("zerorf-vm-no-alpha", "zerorf-vm"))
    cmd = point_command(variant, tmp_path, tmp_path / "w")
    assert cmd[1] == "zerorf-vm" and cmd[cmd.index("--pipeline.model.alpha-weight") + 1] == "0"
    assert cmd.index("--pipeline.model.alpha-weight") < cmd.index("blender-data")  # a trainer flag, not a parser's
    assert not any(flag in c for c in cmd for flag in SIZE_FLAGS)
    assert variant.run(SUITE).key != plain.run(SUITE).key and variant.run(SUITE).key.startswith("zerorf-vm-no-alpha_")
    assert "--pipeline.model.alpha-weight" not in point_command(plain, tmp_path, tmp_path / "w")


def test_the_plan_runs_the_slowest_methods_first_and_a_variant_on_its_scenes_only() -> None:
    points = runner.iteration_plan(SUITE, ["lego", "fern"])
    keys = [p.key for p in points]
    assert keys[:3] == ["lego/zerorf-vm/800it", "fern/zerorf-vm/800it", "lego/zerorf-vm-no-alpha/800it"]
    assert "fern/zerorf-vm-no-alpha/800it" not in keys and {"lego/freenerf/800it", "fern/freenerf/800it"} <= set(keys)
    assert len(keys) == 2 * len(SUITE.equal_time["iterations"]["methods"]) - 1
    assert runner.iteration_plan(SUITE, ["fern"], ["zerorf-vm-no-alpha"]) == []


def test_a_point_records_its_iterations_flags_and_metrics(fake_runs: dict, tmp_path: Path) -> None:  # noqa: F811
    point = runner.TimedPoint("lego", "zerorf-vm-no-alpha", BUDGET)
    row = runner.execute_timed(point, SUITE, tmp_path, tmp_path, tmp_path, 2, "a")
    assert row["budget_iterations"] == 800 and "budget_seconds" not in row and row["invocation"] == "a"
    assert row["flags"] == ["--pipeline.model.alpha-weight", "0"] and row["method"] == "zerorf-vm-no-alpha"
    assert row["iterations"] == 500 and row["seconds_per_iteration"] == pytest.approx(0.11)
    assert (row["psnr"], row["ssim"], row["lpips"]) == (21.0, 0.8, 0.2)
    assert "/zerorf-vm/zerorf-vm-no-alpha_" in row["run_dir"]


def test_the_derived_lines_give_each_gap_beside_the_papers() -> None:
    lines = rep.derived_lines(ROWS, SUITE)
    assert lines[0] == (
        "- fourierf-vm-paper minus tensorf-vm-published, test PSNR: lego +2.25 dB at 800 iterations (paper at full "
        "scale: +3.1 dB); fern -0.50 dB at 800 iterations (paper at full scale: +5.0 dB)."
    )
    assert lines[1] == (
        "- zerorf-vm with minus without its alpha term (zerorf-vm-no-alpha) on lego: +1.25 dB at 150 iterations."
    )
    missing = rep.derived_lines([r for r in ROWS if r["method"] != "zerorf-vm-no-alpha"], SUITE)
    assert missing[1].endswith("on lego: not run at equal iterations.")


def test_time_ratios_take_rows_of_the_baselines_invocation_only() -> None:
    def timed(method: str, seconds: float, invocation: str, iterations: int = 800) -> dict:
        return _row("lego", method, 20.0, iterations) | {"trained_seconds": seconds, "invocation": invocation}

    rows = [
        timed("tensorf-vm-published", 100.0, "a"),
        timed("zerorf-vm", 650.0, "a"),
        timed("fourierf-vm", 40.0, "a"),
        timed("freenerf", 900.0, "b"),  # another invocation: another machine or load
        timed("fourierf-vm-paper", 90.0, "a", 150),  # another budget
    ]
    assert rep.time_ratios(rows, "lego", SUITE) == "lego at 800 iterations: zerorf-vm 6.50 (5.18), fourierf-vm 0.40"
    assert rep.time_ratios(rows[1:], "lego", SUITE) == "lego not timed in one invocation"
    assert rep.time_ratios(ROWS, "lego", SUITE) == "lego not timed in one invocation"  # rows with no invocation
    line = rep.derived_lines(rows, SUITE)[2]
    assert line.startswith("- Training time over tensorf-vm-published's") and "fern not timed" in line


def test_a_gap_compares_rows_of_equal_iterations_only() -> None:
    longer = [*ROWS, _row("lego", "zerorf-vm", 23.0, 800)]  # no 800-iteration row without alpha: 150 it is
    assert rep.gap(longer, "lego", "zerorf-vm", "zerorf-vm-no-alpha") == "+1.25 dB at 150 iterations"
    both = [*longer, _row("lego", "zerorf-vm-no-alpha", 22.5, 800)]  # the most iterations both ran win
    assert rep.gap(both, "lego", "zerorf-vm", "zerorf-vm-no-alpha") == "+0.50 dB at 800 iterations"
    apart = [_row("fern", "fourierf-vm-paper", 18.0, 800), _row("fern", "tensorf-vm-published", 18.5, 150)]
    assert rep.gap(apart, "fern", "fourierf-vm-paper", "tensorf-vm-published") == "not run at equal iterations"
    table = rep.iterations_table(longer, "lego", ["zerorf-vm"])
    assert [line.split(" | ")[4] for line in table if line.startswith("| zerorf-vm |")] == ["800", "150"]


def test_the_section_has_a_table_per_scene_and_says_what_is_missing() -> None:
    lines = rep.equal_iterations_section(ROWS, SUITE)
    text = "\n".join(lines)
    assert lines[0] == f"## {rep.ITERATIONS_TITLE}" and "runs a shorter one" in text and "one invocation" in text
    assert "| fourierf-vm-paper | 21.50 | 0.800 | 0.200 | 800 | 400 | 0.50 |" in lines
    assert "| zerorf-vm-no-alpha | 18.75 | 0.800 | 0.200 | 150 | 75 | 0.50 |" in lines
    assert "| zerorf-vm | not run | | | | | |" in lines  # fern's zerorf-vm: no row
    fern = lines[lines.index("### fern") :]
    assert not any(line.startswith("| zerorf-vm-no-alpha") for line in fern)  # the variant runs on lego only
    assert "No points" in "\n".join(rep.equal_iterations_section([], SUITE))


def test_a_method_outside_the_stage_is_one_clear_error(tmp_path: Path) -> None:
    done = subprocess.run([sys.executable, str(SCRIPT), "equal-time", "--methods", "zerorf-vm-no-alpha",
                           "--work", str(tmp_path)], capture_output=True, text=True)  # fmt: skip
    assert done.returncode != 0 and "freenerf" in done.stderr and "Traceback" not in done.stderr


@pytest.mark.parametrize("budget", [["3m"], ["150it", "300it"]])
def test_a_budget_that_is_not_one_count_of_iterations_is_one_clear_error(tmp_path: Path, budget: list[str]) -> None:
    done = subprocess.run([sys.executable, str(SCRIPT), "equal-iterations", "--budget", *budget,
                           "--work", str(tmp_path)], capture_output=True, text=True)  # fmt: skip
    assert done.returncode != 0 and "200it" in done.stderr and "Traceback" not in done.stderr


def test_a_shorter_budget_plans_every_point_at_it() -> None:
    points = runner.iteration_plan(SUITE, ["lego"], ["zerorf-vm"], "150it")
    assert [p.key for p in points] == ["lego/zerorf-vm/150it"] and points[0].run(SUITE).iters == 150
