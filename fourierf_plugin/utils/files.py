"""Making sure an output can be written before the work that produces it starts."""

from __future__ import annotations

import os
import tempfile
from pathlib import Path

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
