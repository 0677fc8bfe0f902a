"""Folders a command creates for its outputs, remembered so that a command that stops (Ctrl-C, SIGTERM, an error)
removes the ones it made and left empty, and never touches a folder that was there before it."""

from __future__ import annotations

import contextlib
from pathlib import Path
from types import TracebackType

from fourierf_plugin.utils.errors import fail
from fourierf_plugin.utils.files import check_reachable


class NewDirs:
    """The folders this call made, newest last. As a context manager it removes them, if empty, when the block ends
    with an exception (a stop signal included); removal is ``rmdir`` only, so nothing inside a folder is ever lost."""

    def __init__(self) -> None:
        self.made: list[Path] = []

    def make(self, folder: Path, flag: str) -> Path:
        """Create ``folder`` and its missing parents, one at a time, and remember the ones this call created (a
        folder another process makes meanwhile is not ours); an unwritable path is a UserError naming ``flag``."""
        folder = Path(folder)
        check_reachable(folder, [flag, str(folder)])
        for path in [*reversed(folder.parents), folder]:
            if path.is_dir():
                continue
            try:
                path.mkdir()
            except FileExistsError:
                if not path.is_dir():
                    fail(f"cannot write to {folder} ({path} exists and is not a folder)", f"choose a writable {flag}")
                continue  # made by another process meanwhile
            except OSError as err:
                fail(f"cannot write to {folder} ({err.strerror or err})", f"choose a writable {flag}")
            self.made.append(path)
        return folder

    def adopt(self, folder: Path) -> None:
        """Remember a folder made for this call elsewhere (a render folder claimed by creating it)."""
        self.made.append(Path(folder))

    def remove_empty(self) -> None:
        """Remove the remembered folders that are empty, deepest first; a folder holding anything stays."""
        for path in reversed(self.made):
            with contextlib.suppress(OSError):
                path.rmdir()
        self.made.clear()

    def __enter__(self) -> NewDirs:
        return self

    def __exit__(self, kind: type[BaseException] | None, err: BaseException | None, tb: TracebackType | None) -> None:
        if kind is not None:
            self.remove_empty()
