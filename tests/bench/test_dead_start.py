"""benchmarks/dead_start.py: the dead-field criterion, the table of runs that revival changed, and the first steps of a
real (tiny) forward-facing run."""

from __future__ import annotations

import math
import subprocess
import sys
from pathlib import Path
from types import ModuleType

import pytest

from tests.helpers import TINY_FLAGS, load_benchmark
from tests.scenes import write_llff_scene

SCRIPT = Path(__file__).resolve().parents[2] / "benchmarks" / "dead_start.py"


@pytest.fixture(scope="module")
def dead_start() -> ModuleType:
    return load_benchmark("dead_start")


def test_dead_means_still_dark_when_the_count_ends(dead_start: ModuleType) -> None:
    live = [0.3] * 10 + [0.05] * 30
    dead = [0.3] * 40
    late_revival = [0.3] * 28 + [0.05] * 12  # dark for most of the count, lit at its end: came back
    assert not dead_start.is_dead(live, 0.2)
    assert dead_start.is_dead(dead, 0.2)
    assert not dead_start.is_dead(late_revival, 0.2)
    assert dead_start.is_dead([0.05] * 30 + [0.3] * 6 + [0.05] * 4, 0.2)


def _count_row(seed: int, label: str, mse: list[float], device: str = "cpu") -> dict:
    return {"method": "fourierf-vm", "sides": [64, 128], "rays": 1024, "device": device, "seed": seed,
            "label": label, "mse": mse}  # fmt: skip


def test_identity_table_names_the_seeds_revival_changed(dead_start: ModuleType) -> None:
    rows = [
        _count_row(0, "revive", [0.3, 0.1]), _count_row(0, "plain", [0.3, 0.1]),
        _count_row(1, "revive", [0.3, 0.1]), _count_row(1, "plain", [0.3, 0.1 + 1e-9]),
        _count_row(2, "revive", [0.3, 0.2]),  # no plain partner: not compared
        _count_row(3, "revive", [0.3], "cuda"), _count_row(3, "plain", [0.4], "cuda"),  # CUDA: not deterministic
    ]  # fmt: skip
    rows += [_count_row(0, "revive1", [0.3, 0.2]), _count_row(1, "revive1", [0.3, 0.1])]
    table = dead_start.identity_table(rows)
    assert table[0].startswith("| method | grid | rays | ReLU | steps | identical to plain |")
    assert table[2:] == ["| fourierf-vm | 64³ → 128³ | 1024 | revive | 2 | 1 of 2 | 1 |",
                         "| fourierf-vm | 64³ → 128³ | 1024 | revive1 | 2 | 0 of 2 | 0 1 |"]  # fmt: skip
    against_revive1 = dead_start.identity_table(rows, "revive1")
    assert against_revive1[2:] == ["| fourierf-vm | 64³ → 128³ | 1024 | revive | 2 | 1 of 2 | 0 |"]


def test_dark_stretches_are_grouped_per_seed(dead_start: ModuleType) -> None:
    assert dead_start.dark_runs([0, 1, 2, 5, 7, 8]) == [(0, 3), (5, 1), (7, 2)]
    assert dead_start.dark_runs([]) == []
    rows = [_count_row(1, "plain-counted", [0.3] * 10) | {"dark_steps": [0, 1, 2, 7, 8, 9]},
            _count_row(0, "plain-counted", [0.3] * 10) | {"dark_steps": []},
            _count_row(2, "plain", [0.3] * 10)]  # fmt: skip
    table = dead_start.dark_table(rows)
    assert table[2:] == ["| fourierf-vm | 64³ → 128³ | 1024 | cpu | plain-counted | 0: — · 1: 0–2, 7–9+ |"]


def test_first_steps_of_a_tiny_forward_facing_run(tmp_path: Path, dead_start: ModuleType) -> None:
    scene = write_llff_scene(tmp_path / "scene")
    argv = ["fourierf-vm", "--data", str(scene), "--output-dir", str(tmp_path / "out"), "--max-num-iterations", "50",
            *TINY_FLAGS, "llff-data", "--num-views", "3"]  # fmt: skip
    mses, dark = dead_start.first_steps(argv, 4)
    assert len(mses) == len(dark) == 4 and all(math.isfinite(m) and m >= 0 for m in mses)
    plain, plain_dark = dead_start.first_steps(
        [*argv[:-3], "--pipeline.model.field.revive-dead-density", "False", *argv[-3:]], 1
    )
    assert plain[0] == mses[0]  # the first batch is rendered before any update: the same field
    assert plain_dark == dark[:1]  # read off the densities, whatever the ReLU


def test_a_missing_scene_is_one_clear_error(tmp_path: Path) -> None:
    proc = subprocess.run([sys.executable, str(SCRIPT), "count", "--data", str(tmp_path)], capture_output=True,
                          text=True)  # fmt: skip
    assert proc.returncode != 0
    assert "fern not found under" in proc.stderr and "Traceback" not in proc.stderr
