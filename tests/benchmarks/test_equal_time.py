"""The equal-time stage without training: each point's command, its row from a faked run (a too-short budget is a
row, not a failure), and the report's cells, time to a PSNR, speed ratios and figure from made-up rows."""

from __future__ import annotations

import dataclasses
import json
import math
import subprocess
import sys
import xml.etree.ElementTree as ET
from pathlib import Path

import harness
import pytest
import report as rep

from tests.helpers import load_benchmark

runner = load_benchmark("run")
SUITE = harness.load_suite()
SCRIPT = Path(__file__).resolve().parents[2] / "benchmarks" / "run.py"


def _row(scene: str, method: str, budget: str, seconds: float, psnr: float, spi: float = 0.1) -> dict:
    return {
        "key": f"{scene}/{method}/{budget}", "scene": scene, "method": method, "budget": budget,
        "budget_seconds": {"1m": 60.0, "3m": 180.0, "10m": 600.0}[budget], "planned_seconds": seconds * 0.95,
        "trained_seconds": seconds, "iterations": round(seconds / spi), "seconds_per_iteration": spi, "psnr": psnr,
        "ssim": 0.8, "lpips": 0.2, "threads": 1, "jobs": 2, "machine": "cpu, 2 cores", "seconds": seconds + 30,
    }  # fmt: skip


def point_command(point: runner.TimedPoint, data: Path, work: Path) -> list[str]:
    """The training command ``execute_timed`` runs for a point (``train_and_eval``'s, on one thread)."""
    run, scene_data, parser, scene_work, flags = point.train_args(SUITE, data, work)
    return harness.train_command(run, scene_data, scene_work / "runs", parser, flags, threads=runner.THREADS)


def _too_short(scene: str, method: str, budget: str) -> dict:
    row = _row(scene, method, budget, 1.0, 0.0)
    return {k: row[k] for k in ("key", "scene", "method", "budget", "budget_seconds", "threads", "jobs", "machine")} | {
        "too_short": "--time-budget 1m is too short for this run",
        "seconds": 40.0,
    }


ROWS = [
    _row("lego", "tensorf-vm-published", "1m", 57.0, 18.0, spi=0.10),
    _row("lego", "tensorf-vm-published", "3m", 171.0, 20.0, spi=0.10),
    _row("lego", "fourierf-vm-paper", "1m", 57.0, 21.0, spi=0.093),
    _row("lego", "fourierf-vm-paper", "3m", 171.0, 22.5, spi=0.093),
    _too_short("lego", "freenerf", "1m"),
    _row("lego", "freenerf", "3m", 170.0, 15.0, spi=3.57),
    _row("fern", "tensorf-vm-published", "1m", 58.0, 16.0, spi=0.20),
    _row("fern", "fourierf-vm-paper", "1m", 58.0, 17.5, spi=0.186),
    _too_short("fern", "freenerf", "1m"),
]


def test_a_points_command_is_a_users_run_at_its_budget_on_one_thread(tmp_path: Path) -> None:
    cmd = point_command(runner.TimedPoint("lego", "zerorf-vm", "3m"), tmp_path, tmp_path / "w")
    assert cmd[0].endswith("fourierf-train") and cmd[1] == "zerorf-vm"
    assert cmd[cmd.index("--time-budget") + 1] == "3m" and cmd[cmd.index("--threads") + 1] == "1"
    assert "--max-num-iterations" not in cmd and not any("n-voxels" in c or "rays-per-batch" in c for c in cmd)
    assert cmd[cmd.index("--data") + 1] == str(tmp_path / "blender" / "lego")
    parser = cmd[cmd.index("blender-data") :]
    assert parser[1:3] == ["--downscale", "4"]  # the cpu protocol's 100×100
    assert parser[parser.index("--view-ids") + 1 :] == ["27", "76", "97", "99"]
    fern = point_command(runner.TimedPoint("fern", "freenerf", "1m"), tmp_path, tmp_path / "w")
    assert fern[fern.index("llff-data") :] == ["llff-data", "--num-views", "3"]


def test_the_plan_runs_longest_budgets_first() -> None:
    points = runner.timed_plan(SUITE, ["lego", "fern"], ["1m", "30m", "3m"], ["fourierf-vm", "zerorf-vm"])
    assert [p.budget for p in points] == ["30m"] * 4 + ["3m"] * 4 + ["1m"] * 4
    assert {p.method for p in points} == {"fourierf-vm", "zerorf-vm"}
    assert len({p.key for p in points}) == len(points)
    every = runner.timed_plan(SUITE, ["fern"], ["1m"])
    assert [p.method for p in every] == list(SUITE.equal_time["methods"])


@pytest.fixture
def fake_runs(monkeypatch: pytest.MonkeyPatch) -> dict:
    """Training either fails on a too-short budget or writes a run whose metrics end with the done record."""
    state = {"too_short": False}

    def fake_run_timed(cmd: list[str], log: Path, env: dict | None = None) -> tuple[float, float, int]:
        log.parent.mkdir(parents=True, exist_ok=True)
        if cmd[0].endswith("fourierf-train"):
            if state["too_short"]:
                log.write_text("error: --time-budget 1m is too short for this run: 100 iterations, the fewest a "
                               "budget may pick, need about 2m here (~1.2 s per iteration)\n")  # fmt: skip
                return 3.0, 0.1, 2
            log.write_text("device cpu (1 thread), grid\n")
            out, key = Path(cmd[cmd.index("--output-dir") + 1]), cmd[cmd.index("--timestamp") + 1]
            run_dir = out / "lego_tiny" / cmd[1] / key  # the trainer names the folder after the data
            run_dir.mkdir(parents=True)
            (run_dir / "views.json").write_text(json.dumps({"train_view_ids": [27, 76]}))
            done = {"event": "done", "step": 500, "train_seconds": 55.0, "planned_train_seconds": 57.0}
            (run_dir / "metrics.jsonl").write_text(json.dumps({"step": 500, "loss": 0.1}) + "\n" + json.dumps(done))
        else:
            report = {"results": {"psnr": 21.0, "ssim": 0.8, "lpips": 0.2}, "num_views": 8,
                      "timings": {"render_seconds_total": 1.0}}  # fmt: skip
            Path(cmd[cmd.index("--output-path") + 1]).write_text(json.dumps(report))
        return 60.0, 0.5, 0

    monkeypatch.setattr(harness, "run_timed", fake_run_timed)
    return state


def test_a_point_records_planned_and_actual_time_iterations_and_metrics(fake_runs: dict, tmp_path: Path) -> None:
    row = runner.execute_timed(
        runner.TimedPoint("lego", "fourierf-vm", "1m"), SUITE, tmp_path, tmp_path, tmp_path, 2, "a"
    )
    assert (row["budget_seconds"], row["planned_seconds"], row["trained_seconds"]) == (60.0, 57.0, 55.0)
    assert row["iterations"] == 500 and row["seconds_per_iteration"] == pytest.approx(0.11)
    assert (row["psnr"], row["ssim"], row["lpips"], row["threads"], row["jobs"]) == (21.0, 0.8, 0.2, 1, 2)
    assert "too_short" not in row


def test_a_budget_too_short_is_a_row_that_says_so(fake_runs: dict, tmp_path: Path) -> None:
    fake_runs["too_short"] = True
    row = runner.execute_timed(runner.TimedPoint("lego", "freenerf", "1m"), SUITE, tmp_path, tmp_path, tmp_path, 1, "a")
    assert row["too_short"].startswith("--time-budget 1m is too short") and "psnr" not in row
    assert "estimated_seconds_per_iteration" not in row
    assert runner.too_short(tmp_path / "missing.log") is None


def test_time_to_psnr_interpolates_on_log_time() -> None:
    points = [(60.0, 18.0), (180.0, 20.0), (600.0, 21.0)]
    seconds, bound = rep.time_to_psnr(points, 19.0)
    assert seconds == pytest.approx(math.sqrt(60 * 180)) and not bound  # halfway in log time
    assert rep.time_to_psnr(points, 20.0) == (180.0, False)
    assert rep.time_to_psnr(points, 17.0) == (60.0, True)  # reached at the first budget: at most that
    assert rep.time_to_psnr(points, 21.5) is None
    assert rep.time_cell(points, 21.5) == "not reached" and rep.time_cell(points, 17.0) == "≤ 60 s"


def test_the_scene_tables_hold_each_budgets_metrics_and_the_time_to_each_target() -> None:
    suite = dataclasses.replace(SUITE, equal_time={**SUITE.equal_time, "psnr_targets": {"lego": [19.0, 23.0]}})
    lines = rep.scene_tables(ROWS, "lego", suite)
    assert "| fourierf-vm-paper | 21.00 / 0.800 / 0.200 | 22.50 / 0.800 / 0.200 |" in lines
    assert "| fourierf-vm-paper | ≤ 57 s | not reached |" in lines
    assert "| freenerf | too short | 15.00 / 0.800 / 0.200 |" in lines
    assert any(line.startswith("| method | 1m | 3m |") for line in lines)
    timed = [line for line in lines if line.startswith("| tensorf-vm-published |") and "min" in line]
    assert timed == [f"| tensorf-vm-published | {rep.duration(math.sqrt(57 * 171))} | not reached |"]
    assert "| freenerf | not reached | not reached |" in lines


def test_the_section_states_its_command_and_how_long_the_stage_took() -> None:
    text = "\n".join(rep.equal_time_section(ROWS, SUITE))
    assert "Command: `python benchmarks/run.py equal-time" in text and rep.FIGURE in text
    assert f'the last line of "{rep.ITERATIONS_TITLE}"' in text and "Seconds per iteration" not in text
    total = sum(r["seconds"] for r in ROWS)
    assert f"The {len(ROWS)} points took {rep.duration(total)} in all, about {rep.duration(total / 2)} at 2" in text
    assert "No points" in "\n".join(rep.equal_time_section([], SUITE))


def test_points_stopped_at_their_budget_are_counted_with_the_share_of_their_schedule() -> None:
    assert "stopped at their budget" not in "\n".join(rep.equal_time_section(ROWS, SUITE))
    cut = [
        ROWS[0] | {"iterations": 300, "planned_iterations": 600},
        ROWS[1] | {"planned_iterations": ROWS[1]["iterations"]},
    ]
    text = "\n".join(rep.equal_time_section(cut, SUITE))
    assert "stopped at their budget before the end of their schedules: 1, after 50% to 50% of their planned" in text


def test_the_figure_is_svg_with_one_line_per_method_per_scene() -> None:
    root = ET.fromstring(rep.figure(ROWS, SUITE))
    lines = root.findall("{http://www.w3.org/2000/svg}polyline")
    drawn = sorted((line.get("data-scene"), line.get("data-method")) for line in lines)
    expected = sorted({(r["scene"], r["method"]) for r in ROWS if "too_short" not in r})
    assert drawn == expected
    for line in lines:  # as many vertices as the method trained points on the scene, left to right in time
        xs = [float(p.split(",")[0]) for p in line.get("points").split()]
        count = sum(
            r["scene"] == line.get("data-scene") and r["method"] == line.get("data-method") and "too_short" not in r
            for r in ROWS
        )
        assert len(xs) == count and xs == sorted(xs)
    texts = [t.text for t in root.iter("{http://www.w3.org/2000/svg}text")]
    assert "training time (s, log axis)" in texts and "test PSNR (dB)" in texts
    assert {"lego", "fern"} <= set(texts) and {r["method"] for r in ROWS} <= set(texts)  # panels and legend
    assert ET.fromstring(rep.figure([], SUITE)) is not None  # no rows yet: still a well-formed picture


def test_budget_outside_the_equal_time_stage_is_one_clear_error(tmp_path: Path) -> None:
    done = subprocess.run([sys.executable, str(SCRIPT), "sweep", "--budget", "1m", "--work", str(tmp_path)],
                          capture_output=True, text=True)  # fmt: skip
    assert done.returncode != 0 and "--budget" in done.stderr and "Traceback" not in done.stderr


def test_a_budget_that_is_no_duration_is_one_clear_error(tmp_path: Path) -> None:
    data = tmp_path / "data"
    for scene in SUITE.scenes.values():
        (data / scene["path"]).mkdir(parents=True)
    done = subprocess.run([sys.executable, str(SCRIPT), "equal-time", "--budget", "5 minutes", "--data", str(data),
                           "--work", str(tmp_path / "w"), "--results", str(tmp_path / "r.jsonl")],
                          capture_output=True, text=True)  # fmt: skip
    assert done.returncode != 0 and "--budget" in done.stderr and "5 minutes" in done.stderr
    assert "Traceback" not in done.stderr and not (tmp_path / "r.jsonl").exists()
