"""The three-method report (benchmarks/three_methods.py) on made-up numbers, and the bench's extra training flags."""

from __future__ import annotations

from pathlib import Path
from types import ModuleType

import pytest

from fourierf_plugin.bench.report import Curve, headline
from fourierf_plugin.bench.runner import RunTask, Scene, train_command
from fourierf_plugin.bench.sweep import SweepSpec, expand
from tests.helpers import load_benchmark


@pytest.fixture(scope="module")
def three() -> ModuleType:
    return load_benchmark("three_methods")


def _curve(method: str, psnr: float, seconds: float) -> Curve:
    knobs = {"iters": 800, "downscale": 4, "grid_voxels": 128**3, "step_ratio": 0.5, "batch_size": 1024, "seed": 1}
    rows = [
        {"method": method, **knobs, "step": 400, "psnr": psnr - 1.0, "train_seconds_at_step": seconds / 2},
        {"method": method, **knobs, "step": 800, "psnr": psnr, "train_seconds_at_step": seconds,
         "train_seconds_total": seconds, "ssim": 0.8, "lpips": 0.1, "peak_rss_gb": 1.0},
    ]  # fmt: skip
    return Curve(method, rows)


def test_the_papers_ordering_holds_when_the_numbers_say_so(three: ModuleType) -> None:
    curves = [_curve("fourierf-vm", 22.0, 95.0), _curve("tensorf-vm", 20.0, 100.0), _curve("zerorf-vm", 22.3, 520.0)]
    quality, time = three.ordering(curves)
    assert "**holds**" in quality and "zerorf-vm 22.30" in quality
    assert "**holds**" in time and "zerorf-vm 520 s" in time


@pytest.mark.parametrize(
    ("psnr", "seconds", "broken"),
    [
        ({"fourierf-vm": 22.0, "tensorf-vm": 21.8, "zerorf-vm": 22.1}, (95, 100, 520), "quality"),  # not above TensoRF
        ({"fourierf-vm": 22.0, "tensorf-vm": 20.0, "zerorf-vm": 23.0}, (95, 100, 520), "quality"),  # not ≈
        ({"fourierf-vm": 22.0, "tensorf-vm": 20.0, "zerorf-vm": 22.2}, (120, 100, 520), "time"),  # FourieRF slower
        ({"fourierf-vm": 22.0, "tensorf-vm": 20.0, "zerorf-vm": 22.2}, (95, 100, 150), "time"),  # ZeroRF not ≪
    ],
)
def test_the_ordering_names_what_breaks_it(three: ModuleType, psnr: dict, seconds: tuple, broken: str) -> None:
    methods = ("fourierf-vm", "tensorf-vm", "zerorf-vm")
    quality, time = three.ordering([_curve(m, psnr[m], s) for m, s in zip(methods, seconds, strict=True)])
    assert ("does not hold" in quality) == (broken == "quality")
    assert ("does not hold" in time) == (broken == "time")


def test_a_missing_method_is_said_not_guessed(three: ModuleType) -> None:
    (line,) = three.ordering([_curve("fourierf-vm", 22.0, 95.0), _curve("tensorf-vm", 20.0, 100.0)])
    assert "zerorf-vm" in line and "not checked" in line


def test_the_comparison_sets_each_method_beside_the_paper(three: ModuleType) -> None:
    curves = [_curve("zerorf-vm", 21.1, 600.0), _curve("tensorf-vm", 21.4, 120.0), _curve("fourierf-vm", 21.3, 118.0)]
    table = three.comparison_table(curves, three.PAPER["lego"])
    rows = {line.split(" | ")[0].strip("| "): line for line in table[2:]}
    assert list(rows) == ["fourierf-vm", "tensorf-vm", "zerorf-vm"]
    assert "| 22.11 |" in rows["zerorf-vm"] and "| 5.00× | 5.18× |" in rows["zerorf-vm"]
    assert "| 18.66¹ |" in rows["tensorf-vm"] and "| 1.00× | 1.00× |" in rows["tensorf-vm"]
    assert "| 0.93× |" in rows["fourierf-vm"]


def test_the_headline_quotes_each_methods_own_paper_ratio() -> None:
    lines = headline([_curve("tensorf-vm", 21.0, 100.0), _curve("zerorf-vm", 21.0, 700.0)])
    assert lines == ["- zerorf-vm (800 it.): training time 7.00× tensorf-vm's (paper: 5.18×)."]


def test_extra_training_flags_reach_fourierf_train_before_the_parser(tmp_path: Path) -> None:
    (spec,) = expand(SweepSpec(methods=("zerorf-vm",), iters=(20,), eval_points=2))
    scene = Scene(tmp_path, "llff", ("--num-views", "3"))
    cmd = train_command(RunTask(spec, scene, tmp_path, train_args=("--optimizer.lr-grids", "0.08")))
    flag, parser = cmd.index("--optimizer.lr-grids"), cmd.index("llff-data")
    assert cmd[flag + 1] == "0.08" and flag < parser and cmd[parser + 1 :] == ["--num-views", "3"]
