"""Console output: plain progress lines off a terminal, resume-safe percentages, JSONL logs, durations."""

from __future__ import annotations

import io
import json
import math
import re
from pathlib import Path

import pytest
import torch

from fourierf_plugin.utils import console
from fourierf_plugin.utils.console import TrainingProgress, append_jsonl, format_duration, get_console, warn

ANSI = re.compile(r"\x1b\[")
LINE = re.compile(r"^step (\d+)/(\d+) \((\d+)%\)(?: .*)? \| (?:[\d.]+|--) it/s, eta \S+$")


def _run(capsys: pytest.CaptureFixture[str], total: int, start: int = 0, **kw: int) -> list[str]:
    with TrainingProgress(total, start_step=start, interactive=False, **kw) as progress:
        for step in range(start + 1, total + 1):
            progress.update(step, loss=0.01234, psnr=21.456, f=0.65)
    return capsys.readouterr().out.splitlines()


def test_plain_lines_at_expected_steps(capsys: pytest.CaptureFixture[str]) -> None:
    lines = _run(capsys, total=800)
    assert len(lines) == 20  # every 800 // 20 = 40 steps, the last one included
    assert [int(LINE.match(line).group(1)) for line in lines] == list(range(40, 801, 40))  # type: ignore[union-attr]
    assert not any(ANSI.search(line) for line in lines)
    assert "step 400/800 (50%) loss 0.01234 psnr 21.46 f 0.650 | " in lines[9]
    assert lines[-1].startswith("step 800/800 (100%)")


def test_custom_print_every_and_last_step(capsys: pytest.CaptureFixture[str]) -> None:
    lines = _run(capsys, total=10, print_every=4)
    assert [int(LINE.match(line).group(1)) for line in lines] == [4, 8, 10]  # type: ignore[union-attr]


def test_tiny_runs_print_every_step(capsys: pytest.CaptureFixture[str]) -> None:
    assert len(_run(capsys, total=3)) == 3


def test_resume_never_exceeds_100_percent(capsys: pytest.CaptureFixture[str]) -> None:
    lines = _run(capsys, total=100, start=90, print_every=1)
    assert len(lines) == 10
    percents = [int(LINE.match(line).group(3)) for line in lines]  # type: ignore[union-attr]
    assert percents == list(range(91, 101))
    # A trainer overshooting the total (or resuming past it) is clamped too.
    with TrainingProgress(50, start_step=80, interactive=False, print_every=1) as progress:
        progress.update(120, loss=0.1)
    (line,) = capsys.readouterr().out.splitlines()
    assert line.startswith("step 50/50 (100%)")


def test_eta_measures_this_session_only(monkeypatch: pytest.MonkeyPatch) -> None:
    clock = iter([1000.0, 1010.0])  # start, then 10 s later
    monkeypatch.setattr(console.time, "perf_counter", lambda: next(clock))
    progress = TrainingProgress(1000, start_step=900, interactive=False)
    progress.start()
    # 50 steps in 10 s = 5 it/s; 50 left -> 10 s. Counting the resumed 900 steps would claim 95 it/s.
    line = progress.status_line(950, {"loss": 0.5})
    assert line == "step 950/1000 (95%) loss 0.5 | 5.0 it/s, eta 10.0s"


def test_interactive_bar_renders_metrics_and_counts() -> None:
    buffer = io.StringIO()
    fake = console.Console(file=buffer, force_terminal=True, width=160)
    original = console._CONSOLE
    console._CONSOLE = fake
    try:
        with TrainingProgress(200, start_step=50, interactive=True) as progress:
            for step in range(51, 201):
                progress.update(step, loss=0.0123, psnr=21.45, f=0.65)
    finally:
        console._CONSOLE = original
    text = re.sub(r"\x1b\[[0-9;?]*[A-Za-z]", "", buffer.getvalue())
    assert "200/200" in text and "psnr 21.45" in text and "f 0.650" in text and "it/s" in text


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
