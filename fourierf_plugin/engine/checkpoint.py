"""Checkpoint files: atomic saves, pruning to the last few, and safe loading that survives a bad newest file.

Why atomic: a crash or a full disk in the middle of ``torch.save`` must never leave a half-written file under the
final name, nor damage the previous checkpoint; so we write a temp file in the same directory, fsync it and
``os.replace`` it into place. Why ``weights_only``: a checkpoint downloaded from somewhere must not run code.
"""

from __future__ import annotations

import errno
import os
import re
from pathlib import Path
from typing import Any

import torch

from fourierf_plugin.utils.console import warn
from fourierf_plugin.utils.errors import UserError
from fourierf_plugin.utils.interrupt import note_kept
from fourierf_plugin.utils.os_errors import DISK_FULL, disk_full, os_error_in

CHECKPOINT_GLOB = "step-*.ckpt"
_CHECKPOINT_RE = re.compile(r"^step-(\d+)\.ckpt$")
_DIR_FSYNC_UNSUPPORTED = {errno.EINVAL, errno.ENOTSUP, errno.EBADF, errno.EISDIR, errno.EACCES, errno.EPERM}


def checkpoint_name(step: int) -> str:
    """``step-000000123.ckpt``: zero-padded so names sort like steps."""
    if step < 0:
        raise ValueError(f"checkpoint step must be >= 0, got {step}")
    return f"step-{step:09d}.ckpt"


def _step_of(path: Path) -> int | None:
    match = _CHECKPOINT_RE.match(path.name)
    return int(match.group(1)) if match else None


def list_checkpoints(directory: Path) -> list[Path]:
    """Checkpoint files in ``directory`` by step, oldest first; temp files and other names are ignored."""
    directory = Path(directory)
    if not directory.is_dir():
        return []
    found = [(step, p) for p in directory.iterdir() if (step := _step_of(p)) is not None and p.is_file()]
    return [p for _, p in sorted(found)]


def _fsync_directory(directory: Path) -> None:
    """Persist the rename itself; best effort where the platform/filesystem cannot fsync a directory."""
    if os.name == "nt":
        return
    fd = os.open(directory, os.O_RDONLY)
    try:
        os.fsync(fd)
    except OSError as err:
        if err.errno not in _DIR_FSYNC_UNSUPPORTED:
            raise
    finally:
        os.close(fd)


def _remove_quietly(path: Path) -> None:
    try:
        path.unlink()
    except FileNotFoundError:
        pass
    except OSError as err:
        warn(f"could not remove the temporary file {path}: {err}")


_TEMP_RE = re.compile(r"^\.step-\d+\.ckpt\.tmp-(\d+)$")


def _process_alive(pid: int) -> bool:
    """Whether ``pid`` runs (POSIX); elsewhere assume it does, so nothing of a live writer is ever removed."""
    if os.name == "nt":
        return True
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except OSError:  # e.g. EPERM: it exists but belongs to someone else
        return True
    return True


def _sweep_stale_temps(directory: Path) -> None:
    """Remove temp files left by a writer that was killed mid-save (SIGKILL, power loss): each is a partial
    checkpoint that would otherwise stay on disk for good. Files of live processes are left alone."""
    for path in directory.iterdir():
        match = _TEMP_RE.match(path.name)
        if match and int(match.group(1)) != os.getpid() and not _process_alive(int(match.group(1))):
            _remove_quietly(path)


def _prune(directory: Path, keep_last: int, just_written: Path) -> None:
    """Keep ``just_written`` plus the newest ``keep_last - 1`` others; failures only warn (the save succeeded)."""
    if keep_last <= 0:
        return
    others = [p for p in list_checkpoints(directory) if p.name != just_written.name]
    for old in others[: max(0, len(others) - (keep_last - 1))]:
        try:
            old.unlink()
        except FileNotFoundError:
            pass
        except OSError as err:
            warn(f"could not delete the old checkpoint {old}: {err}")


def save_checkpoint(state: dict, directory: Path, step: int, keep_last: int = 3) -> Path:
    """Atomically write ``state`` as ``directory/step-{step:09d}.ckpt`` and keep only the newest ``keep_last``.

    ``keep_last <= 0`` keeps every checkpoint. A disk or permission failure raises :class:`UserError` and leaves
    the earlier checkpoints untouched (and no temp file behind).
    """
    directory = Path(directory)
    final = directory / checkpoint_name(step)
    tmp = directory / f".{final.name}.tmp-{os.getpid()}"
    try:
        directory.mkdir(parents=True, exist_ok=True)
        with open(tmp, "wb") as fh:
            torch.save(state, fh)
            fh.flush()
            os.fsync(fh.fileno())
        os.replace(tmp, final)
        _fsync_directory(directory)
    except BaseException as err:
        _remove_quietly(tmp)
        io_error = os_error_in(err)
        if io_error is None or not isinstance(err, Exception):
            raise
        if io_error.errno in DISK_FULL:
            earlier = list_checkpoints(directory)
            kept = f"; the earlier checkpoint {earlier[-1].name} is intact" if earlier else ""
            resume = f"fourierf-train --load-dir {directory.parent} (after the method's name)"
            raise disk_full(f"{directory} ({final.name})", resume, kept) from err
        raise UserError(
            f"cannot write checkpoint {final.name} in {directory}: {io_error}",
            fix="free disk space, or choose a writable --output-dir",
        ) from err
    note_kept(final, "checkpoint")
    _prune(directory, keep_last, final)
    _sweep_stale_temps(directory)
    return final


def _short(err: BaseException, limit: int = 200) -> str:
    """First line of an exception message (torch's weights_only errors run to paragraphs)."""
    lines = str(err).strip().splitlines()
    text = lines[0] if lines else ""
    text = f"{type(err).__name__}: {text}" if text else type(err).__name__
    return text if len(text) <= limit else text[: limit - 3] + "..."


def load_checkpoint(path: Path) -> dict[str, Any]:
    """Load a checkpoint on CPU without executing code; any unreadable file is a :class:`UserError`."""
    path = Path(path)
    if not path.exists():
        raise UserError(
            f"checkpoint {path} does not exist",
            fix="pass an existing step-*.ckpt file, or the run directory that holds checkpoints/",
        )
    if not path.is_file():
        raise UserError(f"checkpoint {path} is not a file", fix="pass a step-*.ckpt file")
    unreadable_fix = f"delete {path} so the previous checkpoint is used, or retrain"
    try:
        state = torch.load(path, map_location="cpu", weights_only=True)
    except OSError as err:
        raise UserError(
            f"cannot read checkpoint {path}: {err}", fix=f"check its permissions, or {unreadable_fix}"
        ) from err
    except Exception as err:
        raise UserError(
            f"checkpoint {path} is unreadable (truncated or not a fourierf checkpoint): {_short(err)}",
            fix=unreadable_fix,
        ) from err
    problem = checkpoint_problem(state)
    if problem is not None:
        raise UserError(f"checkpoint {path} is not a fourierf checkpoint ({problem})", fix=unreadable_fix)
    return state


def checkpoint_problem(state: object) -> str | None:
    """What makes a loaded object no fourierf checkpoint (None when it is one): a dict with an integer ``step`` >= 0."""
    if not isinstance(state, dict):
        return f"expected a dict with an integer 'step', found {type(state).__name__}"
    step = state.get("step")
    if not isinstance(step, int) or isinstance(step, bool):
        return "expected a dict with an integer 'step'"
    if step < 0:
        return f"its step is {step}, below 0"
    return None


def restore_pipeline(pipeline: Any, state: dict[str, Any], path: Path) -> None:
    """Load a checkpoint's weights into ``pipeline``; a checkpoint without them, or with another model's (missing,
    extra or misshapen entries), is a UserError naming a few of them, not torch's paragraph."""
    stored = state.get("pipeline")
    model = stored.get("model") if isinstance(stored, dict) else None
    if not isinstance(model, dict) or not all(isinstance(v, torch.Tensor) for v in model.values()):
        raise UserError(
            f"checkpoint {path} holds no model weights (no 'pipeline' entry with the model's tensors)",
            fix="pass a step-*.ckpt written by fourierf-train",
        )
    try:
        pipeline.load_state_dict(stored)
    except (RuntimeError, KeyError, ValueError, TypeError) as err:
        expected = set(pipeline.model.state_dict())
        found = set(model)
        missing, extra = sorted(expected - found), sorted(found - expected)
        parts = [
            f"missing {', '.join(missing[:3])}" if missing else "",
            f"unknown {', '.join(extra[:3])}" if extra else "",
        ]
        detail = "; ".join(p for p in parts if p) or _short(err)
        raise UserError(
            f"checkpoint {path} does not hold this run's model ({detail})",
            fix="pass a checkpoint of this run (its checkpoints/ folder), or the config.json it was trained with",
        ) from err


def load_latest_checkpoint(directory: Path) -> tuple[Path, dict[str, Any]]:
    """The newest checkpoint in ``directory`` that loads, skipping (with a warning) unreadable newer ones.

    ``directory`` is the checkpoints folder; a run directory holding ``checkpoints/`` is accepted too.
    """
    directory = Path(directory)
    candidates = list_checkpoints(directory)
    if not candidates and (directory / "checkpoints").is_dir():
        directory = directory / "checkpoints"
        candidates = list_checkpoints(directory)
    for path in reversed(candidates):
        try:
            return path, load_checkpoint(path)
        except UserError as err:
            warn(f"skipping checkpoint {path}: {err.problem}")
    if not directory.is_dir():
        problem = f"checkpoint directory {directory} does not exist"
    elif candidates:
        problem = f"none of the {len(candidates)} checkpoints in {directory} is readable"
    else:
        problem = f"no checkpoints ({CHECKPOINT_GLOB}) in {directory}"
    raise UserError(problem, fix="train first, or pass the run directory that holds checkpoints/")
