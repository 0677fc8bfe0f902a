"""Memory estimates checked before large allocations: an option that cannot fit fails at once, naming the flag.

Why: an oversized grid or render otherwise runs for minutes and dies in an allocation error (or the OOM killer),
with no checkpoint and no hint of which option was too large. In a container the limit that counts is the cgroup's,
not the host's free memory, so both are read and the smaller one wins.
"""

from __future__ import annotations

from pathlib import Path

from fourierf_plugin.utils.errors import fail

GiB = 2**30
CGROUP_ROOT = Path("/sys/fs/cgroup")
UNLIMITED = 2**60
"""cgroup v1 writes "no limit" as a page-rounded 2^63 - 1: any limit above this means none."""


def host_available() -> int | None:
    """Bytes the kernel says can be allocated without swapping (Linux ``MemAvailable``), or None where unknown."""
    try:
        for line in Path("/proc/meminfo").read_text().splitlines():
            if line.startswith("MemAvailable:"):
                return int(line.split()[1]) * 1024
    except (OSError, ValueError, IndexError):
        return None
    return None


def _read_int(path: Path) -> int | None:
    """The integer in a cgroup file; None when the file is missing, unreadable or says ``max``."""
    try:
        text = path.read_text().strip()
    except OSError:
        return None
    return int(text) if text.isdigit() else None


def _reclaimable(stat: Path, key: str) -> int:
    """The page cache the kernel drops before it kills (``inactive_file`` of ``memory.stat``), 0 if unknown."""
    try:
        for line in stat.read_text().splitlines():
            name, _, value = line.partition(" ")
            if name == key and value.strip().isdigit():
                return int(value)
    except OSError:
        return 0
    return 0


def _own_cgroups(proc_cgroup: Path) -> dict[str, str]:
    """This process's cgroup paths from ``/proc/self/cgroup``: ``{"": path}`` for v2, ``{"memory": path}`` for v1."""
    found: dict[str, str] = {}
    try:
        lines = proc_cgroup.read_text().splitlines()
    except OSError:
        return found
    for line in lines:
        parts = line.split(":", 2)
        if len(parts) == 3 and (parts[1] == "" or "memory" in parts[1].split(",")):
            found["" if parts[1] == "" else "memory"] = parts[2]
    return found


def _folders(base: Path, own: str | None) -> list[Path]:
    """``base`` joined with this process's cgroup path and each of its parents, then ``base`` itself (inside a
    container's cgroup namespace the own path is ``/`` and only ``base`` exists)."""
    folders = []
    if own:
        path = base / own.strip("/")
        while path != base and base in path.parents:
            folders.append(path)
            path = path.parent
    return [*folders, base]


def cgroup_available(root: Path = CGROUP_ROOT, proc_cgroup: Path = Path("/proc/self/cgroup")) -> int | None:
    """Bytes this process's memory cgroup still allows (its limit less its use, page cache counted free), the
    tightest over the cgroup and its parents; None where no limit is set (v2 ``memory.max``, v1
    ``memory.limit_in_bytes``)."""
    own = _own_cgroups(proc_cgroup)
    layouts = (
        (root, own.get(""), "memory.max", "memory.current", "inactive_file"),
        (root / "memory", own.get("memory"), "memory.limit_in_bytes", "memory.usage_in_bytes", "total_inactive_file"),
    )
    tightest: int | None = None
    for base, own_path, limit_file, usage_file, cache_key in layouts:
        for folder in _folders(base, own_path):
            limit = _read_int(folder / limit_file)
            if limit is None or limit >= UNLIMITED:
                continue
            used = _read_int(folder / usage_file) or 0
            used = max(0, used - _reclaimable(folder / "memory.stat", cache_key))
            left = max(0, limit - used)
            tightest = left if tightest is None else min(tightest, left)
    return tightest


def available_memory() -> int | None:
    """Bytes this process may still allocate: the smaller of the host's ``MemAvailable`` and what its cgroup's limit
    leaves; None where neither is known."""
    known = [n for n in (host_available(), cgroup_available()) if n is not None]
    return min(known) if known else None


def check_fits(needed: float, what: str, fix: str, available: int | None = None) -> None:
    """A UserError when ``needed`` bytes exceed the memory available now (nothing happens where it is unknown)."""
    free = available_memory() if available is None else available
    if free is not None and needed > free:
        fail(f"{what} needs about {needed / GiB:.1f} GiB, but {free / GiB:.1f} GiB of memory is available", fix)
