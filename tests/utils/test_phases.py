"""Phase timing: exclusive nesting, no-op without a timer, and the trainer's --profile-phases records.

The accounting tests run on a fake clock (the module's ``time.perf_counter``), so exclusive times are checked
exactly, not within a window that a busy machine could miss.
"""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from fourierf_plugin.utils import phases
from fourierf_plugin.utils.phases import PhaseTimer, phase, shares
from tests.helpers import FakeClock, train_tiny


@pytest.fixture
def clock(monkeypatch: pytest.MonkeyPatch) -> FakeClock:
    """The phases module's ``time.perf_counter``, moved by hand."""
    fake = FakeClock()
    monkeypatch.setattr(phases.time, "perf_counter", fake)
    return fake


def test_phase_is_a_no_op_without_an_active_timer(clock: FakeClock) -> None:
    assert phases._active is None
    timer = PhaseTimer(synchronize=False)  # created but never entered: it must stay inactive
    with phase("sampling"):
        clock.now += 5
        with phase("density"):
            clock.now += 5
    assert phases._active is None
    assert clock.reads == 0, "without an active timer a phase does not even read the clock"
    assert timer.take() == {} and timer.totals == {}
    with timer:
        assert phases._active is timer
        with phase("sampling"):
            clock.now += 1
    assert phases._active is None, "leaving the timer deactivates it"
    with phase("density"):  # after the timer was left: not recorded
        clock.now += 7
    assert timer.take() == {"sampling": 1.0}


def test_nested_phases_are_exclusive_and_add_up_to_the_wall_time(clock: FakeClock) -> None:
    timer = PhaseTimer(synchronize=False)
    start = clock.now
    with timer, phase("outer"):
        clock.now += 2
        with phase("inner"):
            clock.now += 3
            with phase("innermost"):
                clock.now += 4
            clock.now += 1
        clock.now += 1
        with phase("inner"):  # a phase entered twice adds up
            clock.now += 5
    wall = clock.now - start
    totals = timer.take()
    assert totals == {"outer": 3.0, "inner": 9.0, "innermost": 4.0}  # nothing counted twice
    assert sum(totals.values()) == wall
    assert shares(totals) == {"outer": 3 / 16, "inner": 9 / 16, "innermost": 4 / 16}
    assert timer.take() == {}  # take() empties the totals


def test_timers_nest_and_restore_the_previous_one(clock: FakeClock) -> None:
    outer, inner = PhaseTimer(synchronize=False), PhaseTimer(synchronize=False)
    with outer:
        with inner, phase("a"):
            clock.now += 2
        assert phases._active is outer
        with phase("b"):
            clock.now += 3
    assert inner.take() == {"a": 2.0} and outer.take() == {"b": 3.0}


def test_shares_sum_to_one() -> None:
    s = shares({"a": 1.0, "b": 3.0})
    assert s == {"a": 0.25, "b": 0.75}
    assert shares({}) == {}


def test_training_with_profile_phases_logs_every_phase(tmp_path: Path) -> None:
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
