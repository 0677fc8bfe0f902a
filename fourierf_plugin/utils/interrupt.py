"""A clean stop for the console scripts: Ctrl-C, SIGTERM or SIGHUP ends the command with one line saying what was
kept, the temporary files removed, exit code 128 + the signal (Ctrl-C: 130) and no traceback; and a full disk, a
symlink loop or an over-long path met on the way is one clear error.

Why a wrapper around ``main``: the writers already remove their temporary siblings when an exception unwinds
through them, so turning each stop signal into an exception (SIGTERM and SIGHUP would otherwise kill the process
before any cleanup) is all a command needs to leave nothing half-written behind.
"""

from __future__ import annotations

import contextlib
import signal
import sys
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import TypeVar

from rich.console import Console
from rich.markup import escape

from fourierf_plugin.utils.os_errors import user_error_for

T = TypeVar("T")

STOP_SIGNALS = tuple(getattr(signal, name) for name in ("SIGINT", "SIGTERM", "SIGHUP") if hasattr(signal, name))
_KEPT: dict[str, Path] = {}


class Interrupted(KeyboardInterrupt):
    """A stop signal, raised where the main thread was; unwinding removes what was being written."""

    def __init__(self, signum: int) -> None:
        super().__init__(signal.Signals(signum).name)
        self.signum = signum


def note_kept(path: Path, kind: str | None = None) -> None:
    """Record a finished output, so an interrupted command can say what it leaves behind; a later output of the
    same ``kind`` (the newest checkpoint) replaces the earlier one in the list."""
    _KEPT[kind or str(path)] = Path(path)


def _raise_stop(signum: int, frame: object) -> None:
    for other in STOP_SIGNALS:  # the stop is under way: later signals must not cut the cleanup short
        signal.signal(other, signal.SIG_IGN)
    raise Interrupted(signum)


@contextlib.contextmanager
def stop_signals_raise() -> Iterator[None]:
    """Within the block each stop signal raises :class:`Interrupted` (the main thread only; elsewhere a no-op)."""
    previous: dict[int, object] = {}
    try:
        for signum in STOP_SIGNALS:
            previous[signum] = signal.signal(signum, _raise_stop)
    except ValueError:  # not the main thread: signals stay as they are
        pass
    try:
        yield
    except KeyboardInterrupt:
        for signum in previous:  # stopping: signals stay ignored until the process ends
            signal.signal(signum, signal.SIG_IGN)
        previous.clear()
        raise
    finally:
        for signum, handler in previous.items():
            signal.signal(signum, handler)  # type: ignore[arg-type]


def stopped_message(command: str, signum: int, kept: list[Path]) -> str:
    """What an interrupted command prints: the signal, and the finished outputs it leaves (or that it left none)."""
    what = "kept " + ", ".join(str(p) for p in kept) if kept else "nothing written"
    return f"{command} interrupted by {signal.Signals(signum).name}; {what} (temporary files removed)"


def stop_cleanly(main: Callable[[], T], command: str, argv: list[str] | None = None) -> Callable[[], T]:
    """``main`` wrapped for a console script: a stop signal ends it with :func:`stopped_message` and exit code
    128 + the signal; an OS failure a user can fix (``user_error_for``) becomes that UserError."""
    words = sys.argv[1:] if argv is None else argv

    def wrapped() -> T:
        _KEPT.clear()
        try:
            with stop_signals_raise():
                return main()
        except KeyboardInterrupt as err:
            number = getattr(err, "signum", signal.SIGINT)
            Console(stderr=True, highlight=False).print(
                escape(stopped_message(command, number, list(_KEPT.values()))), soft_wrap=True
            )
            raise SystemExit(128 + int(number)) from None
        except (OSError, RuntimeError) as err:
            problem = user_error_for(err, words)
            if problem is None:
                raise
            raise problem from err

    return wrapped
