"""One display line per stage of a long job: a spinner or a bar on a terminal while it runs, then a ``✓`` line with
what it did and how long it took (the only output when the console is not a terminal, so logs stay plain)."""

from __future__ import annotations

import time
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field

from rich.console import Console
from rich.markup import escape
from rich.progress import BarColumn, MofNCompleteColumn, Progress, SpinnerColumn, TextColumn, TimeElapsedColumn


@dataclass
class Stage:
    """Handle of a running stage: ``advance`` its count, set ``detail`` for the closing line."""

    title: str
    total: int | None
    detail: str = ""
    done: int = 0
    _progress: Progress | None = field(default=None, repr=False)
    _task: int | None = field(default=None, repr=False)

    def advance(self, count: int = 1) -> None:
        self.done = min(self.done + count, self.total) if self.total is not None else self.done + count
        if self._progress is not None and self._task is not None:
            self._progress.update(self._task, completed=self.done)


class StageDisplay:
    """``with display.stage("matching features") as stage: ...`` for each stage of a job."""

    def __init__(self, console: Console) -> None:
        self.console = console
        self.seconds: dict[str, float] = {}

    @contextmanager
    def stage(self, title: str, total: int | None = None) -> Iterator[Stage]:
        handle = Stage(title, total)
        columns = [SpinnerColumn(), TextColumn("{task.description}")]
        if total is not None:
            columns += [BarColumn(), MofNCompleteColumn()]
        columns.append(TimeElapsedColumn())
        started = time.perf_counter()
        if self.console.is_terminal:
            with Progress(*columns, console=self.console, transient=True) as progress:
                handle._progress = progress
                handle._task = progress.add_task(escape(title), total=total)
                yield handle
        else:  # a live display would only leave blank lines in a log
            yield handle
        self.seconds[title] = elapsed = time.perf_counter() - started
        detail = f": {handle.detail}" if handle.detail else ""
        self.console.print(f"[green]✓[/green] {escape(title)}{escape(detail)} ({elapsed:.1f} s)", soft_wrap=True)
