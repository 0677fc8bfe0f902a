"""Keep freed tensor memory in the process instead of returning it to the kernel after every op.

glibc serves large blocks with ``mmap`` and unmaps them on free; a render or a training step allocates and frees
tens of MB per op, so each op page-faults fresh zeroed pages (measured: a third of the CPU time spent in the
kernel). Raising the mmap and trim thresholds lets the heap recycle those blocks. It is a tuning knob, not a
correctness one: on anything but glibc this does nothing.
"""

from __future__ import annotations

import ctypes
import ctypes.util
import sys

_M_TRIM_THRESHOLD = -1
_M_TOP_PAD = -2
_M_MMAP_THRESHOLD = -3
_MMAP_THRESHOLD_MAX = 32 * 1024 * 1024  # glibc's ceiling for 64-bit builds; larger blocks are always mmapped
_TRIM_THRESHOLD = 1 << 30
_TOP_PAD = 64 * 1024 * 1024


def keep_freed_memory() -> bool:
    """Tune glibc malloc for tensor workloads; returns whether the settings were applied."""
    if not sys.platform.startswith("linux"):
        return False
    name = ctypes.util.find_library("c")
    if name is None:
        return False
    try:
        libc = ctypes.CDLL(name)
        mallopt = libc.mallopt
    except (OSError, AttributeError):
        return False  # not glibc (e.g. musl has no mallopt)
    mallopt.argtypes, mallopt.restype = [ctypes.c_int, ctypes.c_int], ctypes.c_int
    ok = mallopt(_M_MMAP_THRESHOLD, _MMAP_THRESHOLD_MAX) == 1
    ok &= mallopt(_M_TRIM_THRESHOLD, _TRIM_THRESHOLD) == 1
    ok &= mallopt(_M_TOP_PAD, _TOP_PAD) == 1
    return bool(ok)
