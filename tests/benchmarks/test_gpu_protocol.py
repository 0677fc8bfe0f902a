"""``benchmarks/gpu_protocol.py`` runs end to end: at toy size on the CPU it trains, evaluates and reports."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

from tests.helpers import REPO_ROOT

pytestmark = pytest.mark.slow


def test_the_gpu_protocol_script_runs_at_toy_size_on_a_cpu(tmp_path: Path) -> None:
    script = REPO_ROOT / "benchmarks" / "gpu_protocol.py"
    proc = subprocess.run(
        [sys.executable, str(script), "--tiny", "--device", "cpu", "--work", str(tmp_path), "--markdown", "none"],
        capture_output=True, text=True, timeout=300, cwd=REPO_ROOT,
    )  # fmt: skip
    assert proc.returncode == 0, proc.stdout + proc.stderr
    (row,) = [json.loads(line) for line in (tmp_path / "results.jsonl").read_text().splitlines()]
    assert row["protocol"] == "lego" and row["tiny"] and row["device"] == "cpu"
    assert row["peak_gpu_gb"] is None, "no GPU: no GPU memory is claimed"
    assert row["train_seconds"] > 0 and row["final_s_per_it"] > 0 and 0 < row["psnr"] < 60
    assert "| lego (tiny) | cpu |" in proc.stdout and "22.41" in proc.stdout
