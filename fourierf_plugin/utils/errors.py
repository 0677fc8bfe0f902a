"""One error type for everything a user can fix, and the CLI wrapper that turns it into a clean message."""

from __future__ import annotations

import os
import sys
import traceback
from collections.abc import Callable
from typing import NoReturn, TypeVar

from fourierf_plugin.utils.allocator import keep_freed_memory

T = TypeVar("T")

EXIT_USER_ERROR = 2


class UserError(Exception):
    """A problem with the user's input (files, options, data) that they can fix.

    The message names the problem; ``fix`` says what to do about it. Entry points print both and exit 2,
    without a traceback unless ``--verbose`` (or ``FOURIERF_VERBOSE=1``) is given.
    """

    def __init__(self, problem: str, fix: str | None = None) -> None:
        self.problem = problem
        self.fix = fix
        super().__init__(problem if fix is None else f"{problem}\n  fix: {fix}")


def fail(problem: str, fix: str | None = None) -> NoReturn:
    """Raise a :class:`UserError`; reads better at call sites than ``raise UserError(...)``."""
    raise UserError(problem, fix)


def _verbose_requested(argv: list[str]) -> bool:
    return "--verbose" in argv or os.environ.get("FOURIERF_VERBOSE", "") not in ("", "0")


def run_cli(main: Callable[[], T], argv: list[str] | None = None) -> T:
    """Run an entry point; a :class:`UserError` becomes one red message on stderr and exit code 2.

    Every console script starts here, so this is also where the allocator is tuned for tensor work."""
    argv = sys.argv[1:] if argv is None else argv
    keep_freed_memory()
    try:
        return main()
    except UserError as err:
        if _verbose_requested(argv):
            traceback.print_exc()
        from rich.console import Console

        console = Console(stderr=True, highlight=False)
        console.print(f"[bold red]error:[/bold red] {err.problem}", markup=True, soft_wrap=True)
        if err.fix:
            console.print(f"[bold]fix:[/bold] {err.fix}", markup=True, soft_wrap=True)
        sys.exit(EXIT_USER_ERROR)


def strip_verbose(argv: list[str]) -> list[str]:
    """Remove the global ``--verbose`` flag before the rest reaches tyro."""
    return [a for a in argv if a != "--verbose"]
