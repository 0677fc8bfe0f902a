"""Console output: task progress (plain lines off a terminal, a rich bar on one), rates, JSONL logs, durations.

Every progress test runs on a fake clock (``time.perf_counter`` in the console module, the rich console's
``get_time`` for the bar), so what is printed, and when, is exact whatever the machine is doing.
"""

from __future__ import annotations

import io
import json
import math
import re
from pathlib import Path

import pytest
import torch
from rich.console import Console

from fourierf_plugin.utils import console
from fourierf_plugin.utils.console import TaskProgress, append_jsonl, format_duration, get_console, rate_text, warn
from tests.helpers import FakeClock

ANSI = re.compile(r"\x1b\[")
LINE = re.compile(r"^(\w+) (\d+)/(\d+) \((\d+)%\)(?: .*)? \| (?:-- \w+s/s|[\d.]+ \w+s/s|[\d.]+ s/\w+), eta \S+$")


@pytest.fixture
def clock(monkeypatch: pytest.MonkeyPatch) -> FakeClock:
    """The console module's ``time.perf_counter``, frozen (plain output and its speed read only this clock)."""
    fake = FakeClock()
    monkeypatch.setattr(console.time, "perf_counter", fake)
    return fake


def _counts(lines: list[str]) -> list[int]:
    matches = [LINE.match(line) for line in lines]
    assert all(matches), lines
    return [int(m.group(2)) for m in matches]  # type: ignore[union-attr]


def _run(capsys: pytest.CaptureFixture[str], total: int, start: int = 0, **kw: int) -> list[str]:
    with TaskProgress(total, start=start, interactive=False, **kw) as progress:
        for step in range(start + 1, total + 1):
            progress.update(step, loss=0.01234, psnr=21.456, f=0.65)
    return capsys.readouterr().out.splitlines()


# -- plain lines ------------------------------------------------------------------------------------------------------
def test_plain_lines_at_expected_steps(clock: FakeClock, capsys: pytest.CaptureFixture[str]) -> None:
    lines = _run(capsys, total=800)
    assert _counts(lines) == list(range(40, 801, 40))  # every 800 // 20 = 40 steps, the last one included
    assert not any(ANSI.search(line) for line in lines)
    assert lines[9] == "step 400/800 (50%) loss 0.01234 psnr 21.46 f 0.650 | -- steps/s, eta ?"  # no time passed
    assert lines[-1].startswith("step 800/800 (100%)")


def test_custom_print_every_and_last_step(clock: FakeClock, capsys: pytest.CaptureFixture[str]) -> None:
    assert _counts(_run(capsys, total=10, print_every=4)) == [4, 8, 10]


def test_tiny_runs_print_every_step(clock: FakeClock, capsys: pytest.CaptureFixture[str]) -> None:
    assert _counts(_run(capsys, total=3)) == [1, 2, 3]


def test_resume_never_exceeds_100_percent(clock: FakeClock, capsys: pytest.CaptureFixture[str]) -> None:
    lines = _run(capsys, total=100, start=90, print_every=1)
    assert [int(LINE.match(line).group(4)) for line in lines] == list(range(91, 101))  # type: ignore[union-attr]
    # A trainer overshooting the total (or resuming past it) is clamped too.
    with TaskProgress(50, start=80, interactive=False, print_every=1) as progress:
        progress.update(120, loss=0.1)
    (line,) = capsys.readouterr().out.splitlines()
    assert line.startswith("step 50/50 (100%)")


def test_plain_output_never_stays_quiet_longer_than_quiet_seconds(
    clock: FakeClock, capsys: pytest.CaptureFixture[str]
) -> None:
    """One step a second, a line every 100 steps: a line still comes at least every 30 s in between."""
    start = clock.now
    with TaskProgress(1000, interactive=False, print_every=100, quiet_seconds=30.0) as progress:
        for step in range(1, 251):
            clock.now = start + step
            progress.update(step, loss=0.5)
    lines = capsys.readouterr().out.splitlines()
    assert _counts(lines) == [30, 60, 90, 100, 130, 160, 190, 200, 230]
    assert lines[0] == "step 30/1000 (3%) loss 0.5 | 1.0 steps/s, eta 16m10s"


def test_eta_measures_this_session_only(clock: FakeClock) -> None:
    progress = TaskProgress(1000, start=900, interactive=False)
    progress.start()
    clock.now += 10.0
    # 50 steps in 10 s = 5 steps/s; 50 left -> 10 s. Counting the resumed 900 steps would claim 95 steps/s.
    assert progress.status_line(950, {"loss": 0.5}) == "step 950/1000 (95%) loss 0.5 | 5.0 steps/s, eta 10.0s"


def test_frames_slower_than_one_a_second_show_seconds_per_frame(
    clock: FakeClock, capsys: pytest.CaptureFixture[str]
) -> None:
    """What fourierf-render prints off a terminal: ``frame`` counts, seconds per frame, no metrics."""
    with TaskProgress(10, unit="frame", interactive=False) as progress:
        for frame in range(1, 5):
            clock.now += 2.35
            progress.update(frame)
    lines = capsys.readouterr().out.splitlines()
    assert _counts(lines) == [1, 2, 3, 4]
    assert lines[-1] == "frame 4/10 (40%) | 2.35 s/frame, eta 14.1s"


@pytest.mark.parametrize(
    ("per_second", "unit", "expected"),
    [
        (6.14, "step", "6.1 steps/s"),
        (1.0, "step", "1.0 steps/s"),
        (250.0, "frame", "250.0 frames/s"),
        (1 / 2.35, "frame", "2.35 s/frame"),
        (0.5, "step", "2.00 s/step"),
        (None, "step", "-- steps/s"),
        (0.0, "frame", "-- frames/s"),
    ],
)
def test_rate_text(per_second: float | None, unit: str, expected: str) -> None:
    assert rate_text(per_second, unit) == expected


# -- the bar on a terminal --------------------------------------------------------------------------------------------
def _last_bar_frame(
    monkeypatch: pytest.MonkeyPatch, total: int, start: int, end: int, seconds_each: float, unit: str = "step"
) -> str:
    """Drive the bar from ``start`` to ``end`` on a captured terminal whose clock moves ``seconds_each`` per update;
    the bar's last frame as the terminal shows it (escape codes removed)."""
    clock = FakeClock(0.0)
    buffer = io.StringIO()
    terminal = Console(file=buffer, force_terminal=True, width=200, color_system=None, get_time=clock)
    monkeypatch.setattr(console, "_CONSOLE", terminal)
    with TaskProgress(total, start=start, unit=unit, interactive=True) as progress:
        for done in range(start + 1, end + 1):
            clock.now += seconds_each
            progress.update(done, loss=done / 1000, psnr=21.45, f=0.65)
    frames = re.split(r"\r|\n", re.sub(r"\x1b\[[0-9;?]*[A-Za-z]", "", buffer.getvalue()))
    return [frame for frame in frames if frame.strip()][-1]


def test_interactive_bar_shows_counts_latest_metrics_speed_and_eta(
    monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    """Resumed at 50 of 200 and stopped at 120, two steps a second: the bar shows 120/200, the metrics of step 120,
    a speed of this session only (2.0, not counting the 50 resumed steps) and 80 steps / 2 per s = 40 s left."""
    frame = _last_bar_frame(monkeypatch, total=200, start=50, end=120, seconds_each=0.5)
    assert frame.startswith("step 120/200 ")
    assert "loss 0.12 psnr 21.45 f 0.650" in frame
    assert frame.endswith("2.0 steps/s eta 0:00:40")
    assert capsys.readouterr().out == "", "no plain status lines beside the bar"


def test_interactive_bar_of_slow_frames(monkeypatch: pytest.MonkeyPatch) -> None:
    frame = _last_bar_frame(monkeypatch, total=8, start=0, end=3, seconds_each=2.0, unit="frame")
    assert frame.startswith("frame 3/8 ")
    assert frame.endswith("2.00 s/frame eta 0:00:10")  # 5 frames left at 2 s each


# -- other output -----------------------------------------------------------------------------------------------------
def test_warn_goes_to_stderr_literally(capsys: pytest.CaptureFixture[str]) -> None:
    warn("skipping [bold]/runs/step-1.ckpt")
    captured = capsys.readouterr()
    assert captured.out == ""
    assert "warning:" in captured.err and "[bold]/runs/step-1.ckpt" in captured.err


def test_get_console_is_a_singleton() -> None:
    assert get_console() is get_console()


def test_append_jsonl_appends_parseable_lines(tmp_path: Path) -> None:
    path = tmp_path / "logs" / "metrics.jsonl"
    append_jsonl(path, {"step": 1, "loss": 0.5, "note": "multi\nline"})
    append_jsonl(path, {"step": 2, "loss": torch.tensor(0.25), "psnr": float("nan"), "out": tmp_path})
    lines = path.read_text(encoding="utf-8").splitlines()
    assert len(lines) == 2
    records = [json.loads(line) for line in lines]
    assert records[0] == {"step": 1, "loss": 0.5, "note": "multi\nline"}
    assert records[1] == {"step": 2, "loss": 0.25, "psnr": None, "out": str(tmp_path)}


@pytest.mark.parametrize(
    ("seconds", "expected"),
    [
        (0, "0.0s"),
        (45.2, "45.2s"),
        (59.96, "1m00s"),
        (65, "1m05s"),
        (3599.6, "1h00m"),
        (2 * 3600 + 3 * 60 + 10, "2h03m"),
        (3 * 86400 + 4 * 3600, "3d04h"),
        (math.inf, "?"),
        (-1, "?"),
    ],
)
def test_format_duration(seconds: float, expected: str) -> None:
    assert format_duration(seconds) == expected
