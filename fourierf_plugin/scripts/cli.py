"""What every console script shares: a ``UserError`` becomes one clear message and exit code 2, ``--verbose``
shows the traceback, and the allocator is tuned for tensor work."""

from __future__ import annotations

import os
import sys
import traceback
from collections.abc import Callable
from typing import TypeVar

from rich.console import Console
from rich.markup import escape

from fourierf_plugin.accel.allocator import keep_freed_memory
from fourierf_plugin.utils.errors import UserError

T = TypeVar("T")

EXIT_USER_ERROR = 2


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
        console = Console(stderr=True, highlight=False)
        # The message is text, not markup: "pip install '.[colmap]'" must print its brackets.
        console.print(f"[bold red]error:[/bold red] {escape(err.problem)}", markup=True, soft_wrap=True)
        if err.fix:
            console.print(f"[bold]fix:[/bold] {escape(err.fix)}", markup=True, soft_wrap=True)
        sys.exit(EXIT_USER_ERROR)


def strip_verbose(argv: list[str]) -> list[str]:
    """Remove the global ``--verbose`` flag before the rest reaches tyro."""
    return [a for a in argv if a != "--verbose"]
