"""Phase timing: exclusive nesting, no-op without a timer, and the trainer's --profile-phases records."""

from __future__ import annotations

import json
import time
from pathlib import Path

import torch

from fourierf_plugin.utils.phases import PhaseTimer, phase, shares
from tests.helpers import train_tiny


def test_phase_is_a_no_op_without_an_active_timer() -> None:
    with phase("sampling"):
        pass
    timer = PhaseTimer(synchronize=False)
    with phase("sampling"):  # created but never entered: still inactive
        pass
    assert timer.take() == {}


def test_nested_phases_are_exclusive_and_add_up_to_the_wall_time() -> None:
    timer = PhaseTimer(synchronize=False)
    start = time.perf_counter()
    with timer, phase("outer"):
        time.sleep(0.02)
        with phase("inner"):
            time.sleep(0.03)
        time.sleep(0.01)
    wall = time.perf_counter() - start
    totals = timer.take()
    assert 0.03 <= totals["inner"] < 0.03 + 0.02
    assert 0.03 <= totals["outer"] < 0.03 + 0.02  # the 0.03 s inside "inner" is not counted twice
    assert sum(totals.values()) <= wall
    assert timer.take() == {}  # take() empties the totals


def test_timers_nest_and_restore_the_previous_one() -> None:
    outer, inner = PhaseTimer(synchronize=False), PhaseTimer(synchronize=False)
    with outer:
        with inner, phase("a"):
            pass
        with phase("b"):
            pass
    assert set(inner.take()) == {"a"} and set(outer.take()) == {"b"}


def test_shares_sum_to_one() -> None:
    s = shares({"a": 1.0, "b": 3.0})
    assert s == {"a": 0.25, "b": 0.75}
    assert shares({}) == {}


def test_training_with_profile_phases_logs_every_phase(tmp_path: Path) -> None:
    torch.set_num_threads(1)
    _, run_dir = train_tiny(tmp_path, iters=20, extra=["--profile-phases", "True", "--log-every", "10"])
    records = [json.loads(line) for line in (run_dir / "metrics.jsonl").read_text().splitlines()]
    logged = [r for r in records if "phases" in r]
    assert [r["step"] for r in logged] == [10, 20]
    done = records[-1]
    expected = {"fourier_filter", "fourier_filter_backward", "sampling", "density", "appearance", "compositing",
                "losses", "backward", "optimizer", "data", "structure"}  # fmt: skip
    assert expected <= set(done["phases_total"])
    assert all(v >= 0 for v in done["phases_total"].values())
    assert sum(done["phases_total"].values()) <= done["train_seconds"]
    for name in expected:
        assert abs(sum(r["phases"].get(name, 0.0) for r in logged) - done["phases_total"][name]) < 1e-9
