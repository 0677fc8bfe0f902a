"""Terminal output for training: a rich progress bar on a TTY, plain ANSI-free lines elsewhere, and JSONL logs.

Why two modes: progress bars redraw with escape codes, which turn CI logs, pipes and notebook outputs into noise,
so anything that is not an interactive terminal gets one plain line every few steps instead.
"""

from __future__ import annotations

import json
import math
import re
import sys
import time
from pathlib import Path
from types import TracebackType
from typing import Any

from rich.console import Console
from rich.markup import escape
from rich.progress import (
    BarColumn,
    MofNCompleteColumn,
    Progress,
    ProgressColumn,
    Task,
    TextColumn,
    TimeRemainingColumn,
)
from rich.text import Text

from fourierf_plugin.utils.errors import UserError
from fourierf_plugin.utils.files import write_text_atomic

_CONSOLE: Console | None = None
_ERR_CONSOLE: Console | None = None

# Metrics with a natural precision; anything else gets 4 significant digits.
_METRIC_FORMATS = {"psnr": ".2f", "f": ".3f", "ssim": ".4f", "lpips": ".4f", "lr": ".2e"}


CPU_THREADS_NOTE = re.compile(r"(\d+)\s+CPU\s+threads")
"""Reads the count back from ``cpu_threads_note`` in a log (the console may wrap it): benchmark rows record it."""


def cpu_threads_note(threads: int) -> str:
    """How many CPU threads torch computes on, as the logs say it: on a CPU only one thread sums floats in a fixed
    order, so a run's numbers are reproducible only at the count it had."""
    return f"{threads} CPU threads"


def get_console() -> Console:
    """The shared stdout console (rich looks ``sys.stdout`` up at print time, so redirection still works)."""
    global _CONSOLE
    if _CONSOLE is None:
        _CONSOLE = Console(highlight=False)
    return _CONSOLE


def _get_err_console() -> Console:
    global _ERR_CONSOLE
    if _ERR_CONSOLE is None:
        _ERR_CONSOLE = Console(stderr=True, highlight=False)
    return _ERR_CONSOLE


def warn(msg: str) -> None:
    """Print one yellow warning line on stderr; ``msg`` is shown literally (paths may contain ``[``)."""
    _get_err_console().print(f"[bold yellow]warning:[/bold yellow] {escape(msg)}", soft_wrap=True)


def format_duration(seconds: float) -> str:
    """Compact human duration: ``45.2s``, ``1m05s``, ``2h03m``, ``3d04h``; ``?`` when unknown (NaN, inf, < 0)."""
    if not math.isfinite(seconds) or seconds < 0:
        return "?"
    if round(seconds, 1) < 60:
        return f"{seconds:.1f}s"
    total_s = round(seconds)
    if total_s < 3600:
        minutes, secs = divmod(total_s, 60)
        return f"{minutes}m{secs:02d}s"
    total_min = round(seconds / 60)
    if total_min < 24 * 60:
        hours, minutes = divmod(total_min, 60)
        return f"{hours}h{minutes:02d}m"
    days, hours = divmod(round(seconds / 3600), 24)
    return f"{days}d{hours:02d}h"


def format_metrics(metrics: dict[str, Any]) -> str:
    """``loss 0.0123 psnr 21.45 f 0.650``: every metric given, in the given order, compactly."""
    parts = []
    for key, value in metrics.items():
        if isinstance(value, int) and not isinstance(value, bool):
            parts.append(f"{key} {value}")
            continue
        number = float(value)
        spec = _METRIC_FORMATS.get(key, ".4g")
        parts.append(f"{key} {number:{spec}}")
    return " ".join(parts)


def rate_text(per_second: float | None, unit: str) -> str:
    """``6.1 steps/s`` when at least one per second, else ``2.35 s/frame``; ``-- steps/s`` when unknown."""
    if not per_second:
        return f"-- {unit}s/s"
    return f"{per_second:.1f} {unit}s/s" if per_second >= 1.0 else f"{1.0 / per_second:.2f} s/{unit}"


class _RateColumn(ProgressColumn):
    """Units per second over this session (rich only samples advances, so a resumed start is not counted)."""

    def __init__(self, unit: str) -> None:
        super().__init__()
        self.unit = unit

    def render(self, task: Task) -> Text:
        return Text(rate_text(task.speed, self.unit), style="progress.data.speed")


class TaskProgress:
    """Progress of a counted task (training steps, rendered frames): a rich bar on a terminal, plain lines otherwise.

    ``update(done, **metrics)`` takes the count completed so far (``1 .. total``); a count before ``start`` (a
    resumed run) is done but not counted towards the speed and ETA, which measure this session only. Plain output
    prints every ``print_every`` (default: every 5 %) and at least every ``quiet_seconds``, so a log never goes silent.
    """

    def __init__(
        self,
        total: int,
        start: int = 0,
        unit: str = "step",
        interactive: bool | None = None,
        print_every: int | None = None,
        quiet_seconds: float = 30.0,
    ) -> None:
        self.total = max(0, int(total))
        self.start_count = min(max(0, int(start)), self.total)
        self.unit = unit
        self.interactive = sys.stdout.isatty() if interactive is None else interactive
        self.print_every = max(1, self.total // 20) if print_every is None else max(1, int(print_every))
        self.quiet_seconds = quiet_seconds
        self._progress: Progress | None = None
        self._task_id: Any = None
        self._t0: float | None = None
        self._last_print = 0.0

    def __enter__(self) -> TaskProgress:
        self.start()
        return self

    def __exit__(
        self, exc_type: type[BaseException] | None, exc: BaseException | None, tb: TracebackType | None
    ) -> None:
        self.close()

    def start(self) -> None:
        """Start the clock (and the bar); ``update`` calls it if the object is used without ``with``."""
        if self._t0 is not None:
            return
        self._t0 = self._last_print = time.perf_counter()
        if self.interactive:
            self._progress = Progress(
                TextColumn(f"[bold]{self.unit}"),
                MofNCompleteColumn(),
                BarColumn(),
                TextColumn("{task.fields[metrics]}"),
                _RateColumn(self.unit),
                TextColumn("eta"),
                TimeRemainingColumn(),
                console=get_console(),
            )
            self._progress.start()
            self._task_id = self._progress.add_task(
                self.unit, total=max(self.total, 1), completed=self.start_count, metrics=""
            )

    def close(self) -> None:
        if self._progress is not None:
            self._progress.stop()
            self._progress = None

    def update(self, done: int, **metrics: float) -> None:
        """Report that ``done`` units are complete, with the latest metrics (e.g. ``loss``, ``psnr``, ``f``)."""
        self.start()
        done = min(max(0, int(done)), self.total)
        if self._progress is not None:
            self._progress.update(self._task_id, completed=done, metrics=format_metrics(metrics))
            return
        now = time.perf_counter()
        if done % self.print_every == 0 or done >= self.total or now - self._last_print >= self.quiet_seconds:
            self._last_print = now
            print(self.status_line(done, metrics), file=sys.stdout, flush=True)

    def status_line(self, done: int, metrics: dict[str, Any]) -> str:
        """``step 400/800 (50%) loss 0.0123 psnr 21.45 f 0.650 | 6.1 steps/s, eta 1m05s`` (no escape codes)."""
        done = min(max(0, int(done)), self.total)
        percent = 100.0 if self.total == 0 else 100.0 * done / self.total
        elapsed = 0.0 if self._t0 is None else time.perf_counter() - self._t0
        done_here = done - self.start_count
        if done_here > 0 and elapsed > 0:
            rate = done_here / elapsed
            timing = f"{rate_text(rate, self.unit)}, eta {format_duration((self.total - done) / rate)}"
        else:
            timing = f"{rate_text(None, self.unit)}, eta ?"
        text = f"{self.unit} {done}/{self.total} ({percent:.0f}%)"
        shown = format_metrics(metrics)
        if shown:
            text += " " + shown
        return f"{text} | {timing}"


def _jsonable(value: Any) -> Any:
    """Plain-JSON form: 0-d tensors/numpy scalars as numbers, Paths as str, NaN/inf as null (strict JSON)."""
    if isinstance(value, dict):
        return {str(k): _jsonable(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_jsonable(v) for v in value]
    if isinstance(value, Path):
        return str(value)
    if hasattr(value, "item") and callable(value.item) and getattr(value, "ndim", 0) == 0:
        value = value.item()
    elif hasattr(value, "tolist") and callable(value.tolist):
        return _jsonable(value.tolist())
    if isinstance(value, float) and not math.isfinite(value):
        return None
    return value


def append_jsonl(path: Path, record: dict) -> None:
    """Append ``record`` as one JSON line; the file is reopened each call so a crash loses no earlier line."""
    path = Path(path)
    line = json.dumps(_jsonable(record), allow_nan=False, default=str)
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        with path.open("a", encoding="utf-8") as fh:
            fh.write(line + "\n")
            fh.flush()
    except OSError as err:
        raise UserError(
            f"cannot append to the log file {path}: {err}",
            fix="free disk space, or choose a writable --output-dir",
        ) from err


def write_json(path: Path, payload: Any) -> None:
    """Write ``payload`` as indented JSON, atomically (``write_text_atomic``), creating the folder."""
    write_text_atomic(Path(path), json.dumps(_jsonable(payload), indent=2) + "\n")
