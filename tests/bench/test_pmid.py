"""benchmarks/pmid.py on made-up rows: settings are chosen on val alone, the plans skip what a method cannot vary,
and an unknown ``--only`` name is one clear error."""

from __future__ import annotations

import argparse
import subprocess
import sys
from pathlib import Path
from types import ModuleType

import pytest

from tests.helpers import load_benchmark

SCRIPT = Path(__file__).resolve().parents[2] / "benchmarks" / "pmid.py"


@pytest.fixture(scope="module")
def pmid() -> ModuleType:
    return load_benchmark("pmid")


def _row(setting: str, seed: int, val: float, test: float) -> dict:
    return {
        "key": f"lego/fourierf-vm_pcpu-{setting}_800_s{seed}", "scene": "lego", "protocol": "pcpu",
        "method": "fourierf-vm", "setting": setting, "seed": seed, "val_psnr": val, "psnr": test,
    }  # fmt: skip


def test_the_choice_reads_validation_only(pmid: ModuleType) -> None:
    first = pmid.SEEDS[0]
    rows = [
        _row("preset", first, val=21.0, test=30.0),  # best on test: must not be picked
        _row("wd0", first, val=22.0, test=20.0),
        _row("wd0", 1, val=10.0, test=10.0),  # later seeds do not take part in the choice
    ]
    groups = pmid.rows_by({r["key"]: r for r in rows}, "lego", "pcpu", "fourierf-vm")
    assert pmid.chosen_setting(groups) == "wd0"
    assert pmid.chosen_setting({}) is None


def test_plans_skip_curriculum_settings_for_tensorf_and_keep_only(pmid: ModuleType) -> None:
    args = argparse.Namespace(protocol=["pcpu"], scene=["lego"], only=["wd0", "wd0-ramp0.5"])
    plan = {(r.method, r.views) for _, r in pmid.sweep_plan(args)}
    assert plan == {("fourierf-vm", "pcpu-wd0"), ("tensorf-vm", "pcpu-wd0"), ("fourierf-vm", "pcpu-wd0-ramp0.5")}
    args = argparse.Namespace(protocol=["pcpu"], scene=["lego"], only=["wd0-nodecay-ffinal0.7", "wd0-nodecay-occ"])
    plan = {(r.method, r.views) for _, r in pmid.sweep_plan(args)}
    assert ("tensorf-vm", "pcpu-wd0-nodecay-ffinal0.7") not in plan, "a final cutoff is a curriculum setting"
    assert ("tensorf-vm", "pcpu-wd0-nodecay-occ") in plan
    args = argparse.Namespace(protocol=["pmid800"], scene=["lego", "fern"], only=None)
    assert {scene for scene, _ in pmid.sweep_plan(args)} == {"fern"}, "P-MID at 800 iterations is fern's check"


def test_an_unknown_setting_is_one_clear_error(tmp_path: Path) -> None:
    done = subprocess.run(
        [sys.executable, str(SCRIPT), "sweep", "--scene", "lego", "--only", "wd9", "--work", str(tmp_path)],
        capture_output=True,
        text=True,
    )
    assert done.returncode != 0
    assert "--only wd9: no such setting for lego" in done.stderr and "wd0-nodecay" in done.stderr
    assert "Traceback" not in done.stderr
