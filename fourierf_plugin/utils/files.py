"""Making sure an output can be written before the work that produces it starts."""

from __future__ import annotations

import json
import os
import tempfile
from pathlib import Path
from typing import Any

from fourierf_plugin.utils.errors import fail


def check_writable_dir(folder: Path, flag: str) -> None:
    """Create ``folder`` if needed and prove a file can be written in it; a UserError naming ``flag`` otherwise.

    Why before the work: an evaluation or a render that finds out at its end that it cannot write has lost its work.
    """
    folder = Path(folder)
    try:
        folder.mkdir(parents=True, exist_ok=True)
        fd, probe = tempfile.mkstemp(prefix=".write-check-", dir=folder)
        os.close(fd)
        os.unlink(probe)
    except OSError as err:
        fail(f"cannot write to {folder} ({err.strerror or err})", f"choose a writable {flag}")


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


def run_renders_dir(run_dir: Path, name: str, step: int, overwrite: bool) -> Path:
    """RUN/renders/<name>-step<N>/, or with --overwrite that folder again; else the first free ``-1``, ``-2`` ...
    beside it, so a second evaluation or render keeps the first one's pictures."""
    base = run_dir / "renders" / f"{name}-step{step:06d}"
    if overwrite or not base.exists():
        return base
    n = 1
    while base.with_name(f"{base.name}-{n}").exists():
        n += 1
    return base.with_name(f"{base.name}-{n}")
