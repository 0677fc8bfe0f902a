"""Per-run output folders ``output_dir/<scene>/<method>/<timestamp>[-N]/`` that never collide or escape.

Why: scene names come from datasets and timestamps have one-second resolution, so names are sanitized (no path
separators, no ``..``) and the last level is claimed with an atomic ``mkdir(exist_ok=False)``, adding ``-1``,
``-2``, ... when two runs start in the same second.
"""

from __future__ import annotations

import contextlib
import os
import re
from collections.abc import Callable
from datetime import datetime
from pathlib import Path
from typing import Any

from fourierf_plugin.data.dataparser_base import DataparserOutputs
from fourierf_plugin.utils.console import warn
from fourierf_plugin.utils.errors import UserError
from fourierf_plugin.utils.interrupt import note_kept
from fourierf_plugin.utils.os_errors import user_error_for

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
    named = user_error_for(err, ["--output-dir", str(path)], path=path)  # a full disk, a link loop, a long name
    return named or UserError(f"cannot create the run directory {path}: {err}", fix="choose a writable --output-dir")


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
        note_kept(candidate, "run")
        return candidate
    raise UserError(
        f"{_MAX_SUFFIX} runs named {stamp} already exist in {parent}",
        fix="pass a different timestamp, or clean up old runs",
    )


LOCK_NAME = ".lock"
_HELD: dict[str, RunLock] = {}


def _pid_in(path: Path) -> int | None:
    try:
        text = path.read_text().strip()
    except OSError:
        return None
    return int(text) if text.isdigit() else None


class RunLock:
    """A lock file held by this process: an advisory ``flock`` the system drops when the process dies, with its PID
    inside to name it. ``RUN/.lock`` keeps two trainers off one run (they would mix checkpoints and logs); a lock
    beside an output keeps two evaluations from writing one report or render folder."""

    def __init__(self, path: Path, fd: int) -> None:
        self.path = Path(path)
        self._fd: int | None = fd

    def release(self) -> None:
        """Remove the file, then drop the lock (idempotent); the next holder starts from no file at all."""
        if self._fd is None:
            return
        _HELD.pop(os.path.realpath(self.path), None)
        with contextlib.suppress(OSError):
            self.path.unlink()
        os.close(self._fd)  # closing drops the flock
        self._fd = None


def lock_run(run_dir: Path) -> RunLock:
    """Take ``RUN/.lock`` for this process: a run another live process trains is a clear error naming its PID; a
    lock left by a process that no longer runs is taken over with a note."""

    def busy(who: str, pid: int | None) -> UserError:
        return UserError(
            f"the run {run_dir} is being trained by {who} (it holds {Path(run_dir) / LOCK_NAME})",
            fix=f"wait for it to finish, or stop it{f' (kill {pid})' if pid else ''}, then resume",
        )

    return hold_lock(Path(run_dir) / LOCK_NAME, busy, note_stale=True)


def lock_output(target: Path, flag: str) -> RunLock:
    """Take ``.<name>.lock`` beside ``target`` (an output this process is about to write): another live process
    writing the same output is a clear error naming its PID, before any work is done."""

    def busy(who: str, pid: int | None) -> UserError:
        return UserError(
            f"{flag} {target} is being written by {who} (another evaluation of the run?)",
            fix=f"wait for it to finish{f' (or stop it: kill {pid})' if pid else ''}, or choose another {flag}",
        )

    target = Path(target)
    return hold_lock(target.with_name(f".{target.name}.lock"), busy)


def hold_lock(path: Path, busy: Callable[[str, int | None], UserError], note_stale: bool = False) -> RunLock:
    """Lock ``path`` for this process (creating it, with this PID inside); ``busy(who, pid)`` is raised when a live
    process holds it. A process holding it already gets its own lock back."""
    key = os.path.realpath(path)
    if key in _HELD:  # this process holds it already (a trainer made again in the same process)
        return _HELD[key]
    while True:
        try:
            fd = os.open(path, os.O_RDWR | os.O_CREAT, 0o644)
        except OSError as err:
            raise UserError(f"cannot create the lock file {path}: {err}", fix="choose a writable folder") from err
        if not _try_lock(fd, path):
            os.close(fd)
            pid = _pid_in(path)
            raise busy(f"process {pid}" if pid is not None else "another process", pid)
        try:
            same = os.fstat(fd).st_ino == os.stat(path).st_ino
        except FileNotFoundError:
            same = False
        if same:
            break
        os.close(fd)  # the holder removed the file meanwhile: lock the new one
    previous = _pid_in(path)
    if note_stale and previous is not None and previous != os.getpid():
        warn(f"{path} names process {previous}, which no longer runs: this process takes the run over")
    os.ftruncate(fd, 0)
    os.write(fd, f"{os.getpid()}\n".encode())
    lock = _HELD[key] = RunLock(path, fd)
    return lock


def _try_lock(fd: int, path: Path) -> bool:
    """An exclusive non-blocking lock on ``fd``; without ``fcntl`` (Windows), the PID inside decides."""
    try:
        import fcntl
    except ImportError:
        pid = _pid_in(path)
        return pid is None or pid == os.getpid() or not _pid_alive(pid)
    try:
        fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except BlockingIOError:
        return False
    return True


def _pid_alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except OSError:
        return True
    return True


def views_record(scene: DataparserOutputs) -> dict[str, Any]:
    """What ``views.json`` records of the training views: their names and ids, and the image size and camera
    centres that tell a moved copy of the scene from another scene with the same file names."""
    centres = scene.cameras.camera_to_worlds[:, :3, 3].double().tolist()
    return {
        "scene": scene.scene_name,
        "train_view_ids": scene.view_ids,
        "train_image_names": scene.image_names,
        "train_image_size": [int(scene.cameras.width), int(scene.cameras.height)],
        "train_camera_centres": [[round(x, 6) for x in centre] for centre in centres],
    }
