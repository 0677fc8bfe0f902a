"""How often the viewer may render: a cap on the share of wall time its renders take (the live viewer's promise
that training slows by at most ``max_share``)."""

from __future__ import annotations

import time
from collections.abc import Callable


class RenderBudget:
    """After work that took ``s`` seconds, the next may start only ``s / max_share`` seconds after it started, so the
    viewer's share of any stretch of time stays below ``max_share``. ``None`` = no cap (a saved run: nothing to
    slow down).

    Why wall time: on a CPU the render thread competes with training for the same cores, and its cost to training
    is about its own busy time; measuring it is simpler and more honest than predicting it.
    """

    def __init__(self, max_share: float | None, clock: Callable[[], float] = time.perf_counter) -> None:
        if max_share is not None and not 0 < max_share <= 1:
            raise ValueError(f"max_share must be in (0, 1], got {max_share}")
        self.max_share = max_share
        self.clock = clock
        self._next_allowed = 0.0
        self.spent_seconds = 0.0

    def wait_seconds(self) -> float:
        """How long until the next piece of work may start (0: now)."""
        if self.max_share is None:
            return 0.0
        return max(0.0, self._next_allowed - self.clock())

    def charge(self, started: float, seconds: float) -> None:
        """Record work that began at ``started`` (this budget's clock) and took ``seconds``."""
        self.spent_seconds += seconds
        if self.max_share is not None:
            self._next_allowed = max(self._next_allowed, started + seconds / self.max_share)
