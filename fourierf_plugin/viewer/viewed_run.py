"""The model the viewer draws, the step it stands for and the training numbers beside it, shared between threads.

The render thread, mesh exports and (in live mode) snapshot loads all touch the same model; one lock keeps them
apart, and a version number tells the renderer that the picture on screen is out of date.
"""

from __future__ import annotations

import threading
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING

from torch import Tensor

if TYPE_CHECKING:
    from fourierf_plugin.models.fourierf import FourieRFModel


@dataclass
class TrainingProgress:
    """What the live page shows about the run beside the picture."""

    step: int
    max_steps: int
    metrics: dict[str, float] = field(default_factory=dict)
    f_density: float = 1.0
    f_color: float = 1.0
    finished: bool = False
    interrupted: bool = False
    """Finished by Ctrl-C or another stop signal before its last step."""


class ViewedRun:
    """A model to render (the run's own when viewing a saved run; a private copy fed snapshots when live)."""

    def __init__(self, model: FourieRFModel, step: int, run_dir: Path, progress: TrainingProgress | None = None):
        self.model = model
        self.step = step
        self.run_dir = Path(run_dir)
        self.progress = progress
        """None for a saved run; the latest step report of a live one."""
        self.lock = threading.RLock()
        self.version = 0

    @property
    def live(self) -> bool:
        return self.progress is not None

    def run_cutoffs(self) -> tuple[float, float]:
        """The cutoffs the run itself is at (the sliders' upper end)."""
        return self.model.cutoffs(self.step)

    def load_snapshot(self, state: dict[str, Tensor], step: int) -> None:
        """Replace the weights by a snapshot taken at ``step`` (resizing grids as the checkpoint loader does)."""
        with self.lock:
            self.model.load_state_dict(state)
            self.model.eval()
            self.step = step
            self.version += 1
