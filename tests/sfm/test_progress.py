"""One display line per stage: live on a terminal, and the closing line in every case."""

from __future__ import annotations

import io
import time

import pytest
from rich.console import Console

from fourierf_plugin.sfm.progress import StageDisplay


@pytest.mark.parametrize("terminal", [True, False])
def test_each_stage_ends_with_one_line_saying_what_it_did(terminal: bool) -> None:
    out = io.StringIO()
    display = StageDisplay(Console(file=out, force_terminal=terminal, width=120, color_system=None))
    with display.stage("mapping [photos]", total=4) as stage:
        stage.advance(2)
        stage.advance(5)  # more registrations than photos (several models): the count stops at the total
        assert stage.done == 4
        stage.detail = "4 of 4 registered"
    with display.stage("matching") as stage:
        stage.advance()
    text = out.getvalue()
    assert "✓ mapping [photos]: 4 of 4 registered (" in text  # literal brackets survive
    assert "✓ matching (" in text
    assert set(display.seconds) == {"mapping [photos]", "matching"}
    if not terminal:
        assert text.count("\n") == 2  # nothing but the two closing lines in a log


def test_a_polled_count_gives_heartbeat_lines_with_the_time_left_off_a_terminal() -> None:
    out = io.StringIO()
    display = StageDisplay(Console(file=out, force_terminal=False, width=200), heartbeat_s=0.05, poll_s=0.01)
    counts = iter(range(100))
    with display.stage("extracting SIFT features of 40 photos", total=40, unit="photos", poll=lambda: next(counts)):
        time.sleep(0.3)
    lines = out.getvalue().splitlines()
    beats = [line for line in lines if line.startswith("  extracting SIFT features of 40 photos: ")]
    assert beats, lines
    assert all("/40 photos, " in line and " elapsed" in line for line in beats)
    assert any(" left" in line for line in beats)
    assert lines[-1].startswith("✓ extracting SIFT features of 40 photos (")


def test_a_stage_without_a_count_still_says_it_is_running() -> None:
    out = io.StringIO()
    display = StageDisplay(Console(file=out, force_terminal=False, width=200), heartbeat_s=0.05, poll_s=0.01)
    with display.stage("incremental mapping"):
        time.sleep(0.2)
    assert "  incremental mapping: " in out.getvalue() and " elapsed" in out.getvalue()


def test_a_failing_poll_is_ignored_and_the_count_never_goes_back() -> None:
    display = StageDisplay(Console(file=io.StringIO(), force_terminal=True, width=120), poll_s=0.01)
    answers = iter([3, None, 2])

    def poll() -> int | None:
        value = next(answers, 5)
        if value is None:
            raise OSError("database is locked")
        return value

    with display.stage("matching features", total=10, unit="pairs", poll=poll) as stage:
        time.sleep(0.2)
        assert stage.done == 5
        stage.update(1)
        assert stage.done == 5
    assert stage.seconds_left() is not None
