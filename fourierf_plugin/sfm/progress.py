"""One display line per stage of a long job: a bar with the count and the time left on a terminal while it runs, then
a ``✓`` line with what it did and how long it took.

Inside a stage the count comes from the work itself (``advance``, e.g. a mapper's callback) or from ``poll``, a
function a watcher thread calls every ``poll_s`` seconds (e.g. rows COLMAP has written to its database, for calls
that give no callback). Off a terminal (a log, a pipe) a plain heartbeat line every ``heartbeat_s`` seconds says the
count, the elapsed time and the time left, so a long stage is never silent, and no escape codes reach the log.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field

from rich.console import Console
from rich.markup import escape
from rich.progress import (
    BarColumn,
    MofNCompleteColumn,
    Progress,
    SpinnerColumn,
    TextColumn,
    TimeElapsedColumn,
    TimeRemainingColumn,
)

from fourierf_plugin.utils.console import format_duration

Poll = Callable[[], "int | None"]
"""Returns how many units are done so far, or None when it cannot tell right now."""


@dataclass
class Stage:
    """Handle of a running stage: ``advance`` or ``update`` its count, set ``detail`` for the closing line."""

    title: str
    total: int | None
    unit: str = ""
    detail: str = ""
    done: int = 0
    started: float = field(default_factory=time.perf_counter)
    _progress: Progress | None = field(default=None, repr=False)
    _task: int | None = field(default=None, repr=False)

    def advance(self, count: int = 1) -> None:
        self.update(self.done + count)

    def update(self, done: int) -> None:
        """Set the count (at most ``total``; it never goes back)."""
        done = max(self.done, done)
        self.done = min(done, self.total) if self.total is not None else done
        if self._progress is not None and self._task is not None:
            self._progress.update(self._task, completed=self.done)

    def seconds_left(self) -> float | None:
        """The time left at the pace so far; None before the first unit or without a total."""
        if self.total is None or self.done <= 0:
            return None
        return (time.perf_counter() - self.started) / self.done * (self.total - self.done)

    def heartbeat(self) -> str:
        """One plain line: the count, the elapsed time and, when known, the time left."""
        elapsed = format_duration(time.perf_counter() - self.started)
        if self.total is None:
            count = f"{self.done} {self.unit}".strip() + ", " if self.done else ""
            return f"  {self.title}: {count}{elapsed} elapsed"
        left = self.seconds_left()
        eta = "" if left is None else f", about {format_duration(left)} left"
        return f"  {self.title}: {self.done}/{self.total} {self.unit}".rstrip() + f", {elapsed} elapsed{eta}"


class StageDisplay:
    """``with display.stage("matching features", total=n, poll=count) as stage: ...`` for each stage of a job."""

    def __init__(self, console: Console, heartbeat_s: float = 10.0, poll_s: float = 0.5) -> None:
        self.console = console
        self.heartbeat_s = heartbeat_s
        self.poll_s = poll_s
        self.seconds: dict[str, float] = {}

    def _watch(self, handle: Stage, poll: Poll | None, stop: threading.Event, live: bool) -> None:
        """The watcher thread: polls the count and, off a terminal, prints the heartbeat lines."""
        next_beat = time.perf_counter() + self.heartbeat_s
        while not stop.wait(min(self.poll_s, self.heartbeat_s)):
            if poll is not None:
                try:
                    count = poll()
                except Exception:  # a count that cannot be read now is read at the next poll
                    count = None
                if count is not None:
                    handle.update(count)
            if not live and time.perf_counter() >= next_beat:
                next_beat += self.heartbeat_s
                self.console.print(handle.heartbeat(), soft_wrap=True, markup=False, highlight=False)

    @contextmanager
    def stage(self, title: str, total: int | None = None, unit: str = "", poll: Poll | None = None) -> Iterator[Stage]:
        handle = Stage(title, total, unit)
        live = self.console.is_terminal
        stop = threading.Event()
        watcher = threading.Thread(target=self._watch, args=(handle, poll, stop, live), daemon=True)
        try:
            if live:
                columns = [SpinnerColumn(), TextColumn("{task.description}")]
                if total is not None:
                    columns += [BarColumn(), MofNCompleteColumn(), TextColumn(escape(unit)), TimeRemainingColumn()]
                columns.append(TimeElapsedColumn())
                with Progress(*columns, console=self.console, transient=True) as progress:
                    handle._progress = progress
                    handle._task = progress.add_task(escape(title), total=total)
                    watcher.start()
                    yield handle
            else:  # a live display would only leave blank lines in a log: heartbeat lines instead
                watcher.start()
                yield handle
        finally:
            stop.set()
            if watcher.is_alive():
                watcher.join()
        self.seconds[title] = elapsed = time.perf_counter() - handle.started
        detail = f": {handle.detail}" if handle.detail else ""
        self.console.print(f"[green]✓[/green] {escape(title)}{escape(detail)} ({elapsed:.1f} s)", soft_wrap=True)
