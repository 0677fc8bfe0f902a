"""Failures of the machine a user can fix (a full disk, a symlink loop, an over-long file name) as one clear message.

Why one place: such an error can surface anywhere a path is touched (a parser's ``stat``, a render's ``imwrite``,
``torch.save``); every entry point turns it into the same :class:`UserError` naming the path and the flag it came
from, instead of a traceback.
"""

from __future__ import annotations

import errno
import os
import re
from pathlib import Path

from fourierf_plugin.utils.errors import UserError

DISK_FULL = frozenset({errno.ENOSPC, getattr(errno, "EDQUOT", errno.ENOSPC)})
_PATHLIB_LOOP = re.compile(r"^Symlink loop from '(.*)'$")


def os_error_in(err: BaseException) -> OSError | None:
    """The OSError behind ``err`` (itself, or its cause or context: torch re-raises a failed write as RuntimeError)."""
    seen: set[int] = set()
    current: BaseException | None = err
    while current is not None and id(current) not in seen:
        if isinstance(current, OSError):
            return current
        seen.add(id(current))
        current = current.__cause__ or current.__context__
    return None


def flag_for(path: str | os.PathLike[str], argv: list[str]) -> str | None:
    """The command-line flag whose value ``path`` is, or lies under (``--data X`` for ``X/transforms.json``)."""
    target = os.path.abspath(path)
    best: tuple[int, str] | None = None
    for i, word in enumerate(argv):
        flag, _, value = word.partition("=")
        if not flag.startswith("--"):
            continue
        if not value and i + 1 < len(argv):
            value = argv[i + 1]
        if not value or value.startswith("--"):
            continue
        given = os.path.abspath(value)
        under = target == given or target.startswith(given.rstrip(os.sep) + os.sep)
        if under and (best is None or len(given) > best[0]):
            best = (len(given), flag)
    return None if best is None else best[1]


def disk_full(path: Path | str, resume: str | None = None, kept: str = "") -> UserError:
    """The one message for a write that found the disk full: where, that nothing half-written was kept (and
    ``kept``: what earlier output is intact), and how to go on."""
    then = f"then resume: {resume}" if resume else "then run the command again"
    return UserError(f"disk full at {path}: nothing half-written was kept{kept}", f"free space on that disk, {then}")


def user_error_for(
    err: BaseException, argv: list[str] | None = None, path: Path | str | None = None, resume: str | None = None
) -> UserError | None:
    """The UserError for a full disk, a symlink loop or an over-long path behind ``err`` (None for anything else).

    ``path`` names the output (else the file the error names: a temporary sibling is no name to show); ``argv``
    lets the message name the flag the path came from; ``resume`` is the command that continues the work.
    """
    loop = _PATHLIB_LOOP.match(str(err)) if isinstance(err, RuntimeError) else None
    if loop is not None:
        return _path_error(loop.group(1), errno.ELOOP, argv or [])
    found = os_error_in(err)
    if found is None:
        return None
    where = path if path is not None else found.filename
    if found.errno in DISK_FULL:
        return disk_full(where if where is not None else "the output's disk", resume)
    if found.errno in (errno.ELOOP, errno.ENAMETOOLONG) and where is not None:
        return _path_error(where, found.errno, argv or [])
    return None


def _path_error(path: str | os.PathLike[str], code: int, argv: list[str]) -> UserError:
    flag = flag_for(path, argv)
    named = f"{flag} {path}" if flag else str(path)
    if code == errno.ELOOP:
        return UserError(
            f"{named} goes round a loop of symbolic links",
            f"point {flag or 'it'} at a real folder (ls -l shows where each link leads)",
        )
    longest = max((len(os.fsencode(part)) for part in Path(path).parts), default=0)
    return UserError(
        f"{named} has a name longer than the file system allows ({longest} bytes in one part; most allow 255)",
        f"choose a shorter {flag or 'path'}",
    )
