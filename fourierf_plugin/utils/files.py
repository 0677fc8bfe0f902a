"""Making sure an output can be written before the work that produces it starts."""

from __future__ import annotations

import itertools
import json
import os
import sys
import tempfile
from pathlib import Path
from typing import Any

from fourierf_plugin.utils.errors import fail
from fourierf_plugin.utils.os_errors import user_error_for


def check_reachable(path: Path, argv: list[str] | None = None) -> None:
    """A UserError when ``path`` lies past a symlink loop or has an over-long name (``Path.is_file`` would only say
    False, and the user would read "not found"); the flag it came from is named from ``argv`` (default: the
    command line). A path that does not exist passes: the caller says what it expected there."""
    try:
        os.stat(path)
    except OSError as err:
        problem = user_error_for(err, sys.argv[1:] if argv is None else argv, path=path)
        if problem is not None:
            raise problem from err


def check_writable_dir(folder: Path, flag: str) -> None:
    """Create ``folder`` if needed and prove a file can be written in it; a UserError naming ``flag`` otherwise.

    Why before the work: an evaluation or a render that finds out at its end that it cannot write has lost its work.
    """
    folder = Path(folder)
    check_reachable(folder, [flag, str(folder)])  # a symlink loop said as such (mkdir would only say "exists")
    try:
        folder.mkdir(parents=True, exist_ok=True)
        fd, probe = tempfile.mkstemp(prefix=".write-check-", dir=folder)
        os.close(fd)
        os.unlink(probe)
    except OSError as err:
        fail(f"cannot write to {folder} ({err.strerror or err})", f"choose a writable {flag}")


def write_text_atomic(path: Path, text: str, resume: str | None = None) -> None:
    """Write ``text`` to ``path`` through a temporary sibling renamed into place, so ``path`` is either the old file
    or the whole new one; the sibling is removed if anything stops the write, and a full disk is one clear error
    (``resume``: the command that continues the work)."""
    path = Path(path)
    tmp = path.with_name(f".{path.name}.tmp-{os.getpid()}")
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        with open(tmp, "w", encoding="utf-8") as fh:
            fh.write(text)
            fh.flush()
            os.fsync(fh.fileno())
        os.replace(tmp, path)
    except BaseException as err:
        tmp.unlink(missing_ok=True)
        problem = user_error_for(err, path=path, resume=resume) if isinstance(err, OSError) else None
        if problem is None:
            raise
        raise problem from err


def read_json_object(path: Path, fix: str, holds: str) -> dict[str, Any]:
    """The JSON object in ``path``; a UserError naming the file (and line) when it is unreadable, not JSON, or not an
    object (``holds`` says what the object should hold)."""
    try:
        content: Any = json.loads(path.read_text(encoding="utf-8"))
    except json.JSONDecodeError as err:
        fail(f"{path} is not valid JSON: {err.msg} at line {err.lineno}, column {err.colno}", fix)
    except RecursionError:
        fail(f"{path} nests its JSON too deeply to be read (a damaged or hostile file)", fix)
    except (UnicodeDecodeError, OSError) as err:
        fail(f"cannot read {path}: {err}", fix)
    if not isinstance(content, dict):
        fail(f"{path} must hold a JSON object with {holds}", fix)
    return content


def run_renders_dir(run_dir: Path, name: str, step: int, overwrite: bool, claim: bool = False) -> Path:
    """RUN/renders/<name>-step<N>/, or with --overwrite that folder again; else the first free ``-1``, ``-2`` ...
    beside it, so a second evaluation or render keeps the first one's pictures. With ``claim`` the free folder is
    created here (empty, atomically), so two commands started together never pick the same one."""
    base = run_dir / "renders" / f"{name}-step{step:06d}"
    if overwrite:
        return base
    for n in itertools.count():
        candidate = base if n == 0 else base.with_name(f"{base.name}-{n}")
        if not claim and not candidate.exists():
            return candidate
        if claim:
            try:
                candidate.mkdir(parents=True)
            except FileExistsError:
                continue
            except OSError as err:
                fail(f"cannot create {candidate} ({err.strerror or err})", "check the run folder can be written")
            return candidate
    raise AssertionError("unreachable")  # pragma: no cover
