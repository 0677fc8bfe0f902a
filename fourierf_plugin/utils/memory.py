"""Memory estimates checked before large allocations: an option that cannot fit fails at once, naming the flag.

Why: an oversized grid or render otherwise runs for minutes and dies in an allocation error (or the OOM killer),
with no checkpoint and no hint of which option was too large.
"""

from __future__ import annotations

from pathlib import Path

from fourierf_plugin.utils.errors import fail

GiB = 2**30


def available_memory() -> int | None:
    """Bytes the kernel says can be allocated without swapping (Linux ``MemAvailable``), or None where unknown."""
    try:
        for line in Path("/proc/meminfo").read_text().splitlines():
            if line.startswith("MemAvailable:"):
                return int(line.split()[1]) * 1024
    except (OSError, ValueError, IndexError):
        return None
    return None


def check_fits(needed: float, what: str, fix: str, available: int | None = None) -> None:
    """A UserError when ``needed`` bytes exceed the memory available now (nothing happens where it is unknown)."""
    free = available_memory() if available is None else available
    if free is not None and needed > free:
        fail(f"{what} needs about {needed / GiB:.1f} GiB, but {free / GiB:.1f} GiB of memory is available", fix)
