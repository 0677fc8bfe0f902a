"""A run whose density field never lights ends with a clear error and a fix, not with the success line."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from fourierf_plugin.engine.health import MIN_ITERATIONS_TO_JUDGE
from fourierf_plugin.scripts import train
from tests.helpers import TINY_FLAGS, TINY_SCENE, cli_exit_code


@pytest.mark.slow
def test_a_field_forced_dark_ends_with_the_dead_field_message(tmp_path: Path, capsys) -> None:
    args = [
        "tensorf-vm", "--data", str(TINY_SCENE), "--output-dir", str(tmp_path), "--timestamp", "dark",
        "--max-num-iterations", str(MIN_ITERATIONS_TO_JUDGE), "--threads", "1", *TINY_FLAGS,
        "--pipeline.model.field.density-shift", "-80",  # softplus(-80): no density can ever show
    ]  # fmt: skip
    assert cli_exit_code(train.main, args) == 2
    out = capsys.readouterr()
    text = out.out + out.err
    assert "the density field is empty" in text or "flat colour" in text
    assert "fix:" in text and "Traceback" not in text
    assert f"trained {MIN_ITERATIONS_TO_JUDGE} iterations" not in text
    records = [json.loads(line) for line in (tmp_path / "lego_tiny" / "tensorf-vm" / "dark" / "metrics.jsonl").open()]
    assert records[-1]["event"] == "dead_field"
