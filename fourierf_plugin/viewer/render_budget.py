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


class PreviewPacer:
    """Picks how many pixels a preview renders so that it takes about ``target_seconds``.

    A preview's time is about proportional to its rays, and what a ray costs depends on the machine, its load (a
    browser or a training run on the same cores) and the view; so the cost per ray is learnt from the previews
    already rendered (the mean of the last estimate and the newest) and each preview renders the share of each side
    that fits the target, between ``min_scale`` and 1, scaled up to the preview size afterwards. Work around each
    picture that is not the render (a snapshot, sending it) is learnt too (``observe_overhead``) and taken off the
    target, down to a quarter of it."""

    def __init__(self, target_seconds: float, min_scale: float = 0.25, first_scale: float = 0.5) -> None:
        if not target_seconds > 0:
            raise ValueError(f"target_seconds must be > 0, got {target_seconds}")
        if not 0 < min_scale <= first_scale <= 1:
            raise ValueError(f"need 0 < min_scale <= first_scale <= 1, got {min_scale} and {first_scale}")
        self.target_seconds = target_seconds
        self.min_scale = min_scale
        self.first_scale = first_scale
        self.seconds_per_ray: float | None = None
        self.overhead_seconds = 0.0

    def render_size(self, width: int, height: int) -> tuple[int, int]:
        """(width, height) to render for a preview shown at ``width`` × ``height``."""
        if self.seconds_per_ray is None:
            scale = self.first_scale
        else:
            target = max(0.25 * self.target_seconds, self.target_seconds - self.overhead_seconds)
            fit = (target / (self.seconds_per_ray * width * height)) ** 0.5
            scale = min(1.0, max(self.min_scale, fit))
        return max(1, round(width * scale)), max(1, round(height * scale))

    def observe(self, rays: int, seconds: float) -> None:
        """A preview of ``rays`` rays took ``seconds``."""
        if rays <= 0 or seconds <= 0:
            return
        newest = seconds / rays
        self.seconds_per_ray = newest if self.seconds_per_ray is None else 0.5 * (self.seconds_per_ray + newest)

    def observe_overhead(self, seconds: float) -> None:
        """A picture's work besides its render took ``seconds``."""
        if seconds >= 0:
            self.overhead_seconds = 0.5 * (self.overhead_seconds + seconds)
