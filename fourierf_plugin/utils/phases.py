"""Per-phase wall-time accounting for one training iteration (fourier filtering, sampling, field queries, ...).

Code marks its phases with ``with phase("sampling"):``; that is a no-op costing one global read unless a
:class:`PhaseTimer` is active (``with timer:``), like ``torch.profiler.record_function``. Phases nest and time is
*exclusive*: while an inner phase runs the outer one is paused, so the totals add up to the wall time of the timed
region and a share is simply ``total[name] / sum(total)``. On CUDA the timer synchronises at every boundary so
asynchronous kernels are charged to the phase that launched them (which slows the run a little: profile on demand).
"""

from __future__ import annotations

import time
from collections import defaultdict
from collections.abc import Iterator
from contextlib import contextmanager

import torch

_active: PhaseTimer | None = None


class PhaseTimer:
    """Exclusive seconds per phase name, accumulated until :meth:`take` empties them."""

    def __init__(self, synchronize: bool | None = None) -> None:
        self.synchronize = torch.cuda.is_available() if synchronize is None else synchronize
        self.totals: defaultdict[str, float] = defaultdict(float)
        self._stack: list[tuple[str, float]] = []
        self._previous: PhaseTimer | None = None

    def _now(self) -> float:
        if self.synchronize:
            torch.cuda.synchronize()
        return time.perf_counter()

    def enter(self, name: str) -> None:
        now = self._now()
        if self._stack:  # pause the enclosing phase
            outer, since = self._stack[-1]
            self.totals[outer] += now - since
        self._stack.append((name, now))

    def exit(self) -> None:
        now = self._now()
        name, since = self._stack.pop()
        self.totals[name] += now - since
        if self._stack:  # resume the enclosing phase
            self._stack[-1] = (self._stack[-1][0], now)

    def take(self) -> dict[str, float]:
        """The totals so far (seconds per phase), then start again from zero."""
        out = dict(self.totals)
        self.totals.clear()
        return out

    def __enter__(self) -> PhaseTimer:
        global _active
        self._previous, _active = _active, self
        return self

    def __exit__(self, *exc: object) -> None:
        global _active
        _active = self._previous


@contextmanager
def phase(name: str) -> Iterator[None]:
    """Charge the enclosed code to ``name`` in the active timer (nothing happens when none is active)."""
    timer = _active
    if timer is None:
        yield
        return
    timer.enter(name)
    try:
        yield
    finally:
        timer.exit()


def shares(totals: dict[str, float]) -> dict[str, float]:
    """Each phase's share of the summed time (empty totals give an empty dict)."""
    whole = sum(totals.values())
    return {k: v / whole for k, v in totals.items()} if whole > 0 else {}
