"""One display line per stage: live on a terminal, and the closing line in every case."""

from __future__ import annotations

import io

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
