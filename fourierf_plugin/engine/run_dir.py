"""Per-run output folders ``output_dir/<scene>/<method>/<timestamp>[-N]/`` that never collide or escape.

Why: scene names come from datasets and timestamps have one-second resolution, so names are sanitized (no path
separators, no ``..``) and the last level is claimed with an atomic ``mkdir(exist_ok=False)``, adding ``-1``,
``-2``, ... when two runs start in the same second.
"""

from __future__ import annotations

import os
import re
from datetime import datetime
from pathlib import Path

from fourierf_plugin.utils.errors import UserError

MAX_NAME_LEN = 100
_MAX_SUFFIX = 10_000
_UNSAFE = re.compile(r"[^A-Za-z0-9._-]")


def sanitize_name(name: str) -> str:
    """A single safe path component: ``[A-Za-z0-9._-]`` only, at most 100 chars, never empty, ``.`` or ``..``."""
    safe = _UNSAFE.sub("_", str(name))[:MAX_NAME_LEN]
    if set(safe) <= {"."}:  # "", ".", "..", "...": special or confusing as a folder name
        safe = "_" * max(1, len(safe))
    return safe


def unique_safe_name(name: str, index: int, taken: set[str]) -> str:
    """``sanitize_name(name)``, with ``_<index>`` (then ``_<index+1>``, ...) appended while it is already taken.

    Why: dataset names like ``a:b`` and ``a?b`` both become ``a_b``; without this the second render would silently
    overwrite the first. The result is added to ``taken``.
    """
    safe = sanitize_name(name)
    candidate, n = safe, index
    while candidate in taken:
        candidate = f"{safe[: MAX_NAME_LEN - 12]}_{n:05d}"
        n += 1
    taken.add(candidate)
    return candidate


def timestamp_now() -> str:
    """Local time as ``2024-05-01_134502`` (sorts chronologically, valid on every filesystem)."""
    return datetime.now().strftime("%Y-%m-%d_%H%M%S")


def _is_inside(path: Path, root: Path) -> bool:
    """Lexical containment after normalising ``..``; symlinks the user set up under ``root`` are respected."""
    path_abs = Path(os.path.abspath(path))
    root_abs = Path(os.path.abspath(root))
    return path_abs == root_abs or root_abs in path_abs.parents


def _unwritable(path: Path, err: OSError) -> UserError:
    return UserError(f"cannot create the run directory {path}: {err}", fix="choose a writable --output-dir")


def make_run_dir(output_dir: Path, scene: str, method: str, timestamp: str | None = None) -> Path:
    """Create and return a fresh ``output_dir/<scene>/<method>/<timestamp>[-N]/`` (race-safe across processes)."""
    output_dir = Path(output_dir)
    parent = output_dir / sanitize_name(scene) / sanitize_name(method)
    stamp = sanitize_name(timestamp if timestamp is not None else timestamp_now())
    try:
        parent.mkdir(parents=True, exist_ok=True)
    except OSError as err:
        raise _unwritable(parent, err) from err
    for suffix in range(_MAX_SUFFIX):
        candidate = parent / (stamp if suffix == 0 else f"{stamp}-{suffix}")
        if not _is_inside(candidate, output_dir):
            raise AssertionError(f"run directory {candidate} escapes {output_dir}")
        try:
            candidate.mkdir(parents=False, exist_ok=False)
        except FileExistsError:
            continue
        except OSError as err:
            raise _unwritable(candidate, err) from err
        return candidate
    raise UserError(
        f"{_MAX_SUFFIX} runs named {stamp} already exist in {parent}",
        fix="pass a different timestamp, or clean up old runs",
    )
