"""One error type for everything a user can fix (the console scripts turn it into a clean message)."""

from __future__ import annotations

from typing import NoReturn


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
