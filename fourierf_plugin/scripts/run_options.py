"""Which trained run a command works on: the options ``fourierf-eval``, ``fourierf-render`` and ``fourierf-export``
share, and the one way they load it."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Literal

from fourierf_plugin.engine.loading import LoadedRun, load_run
from fourierf_plugin.method_configs import config_registry


@dataclass
class RunOptions:
    load_config: Path
    """config.json of a training run."""
    checkpoint: Path | None = None
    """A specific checkpoint (default: the run's latest)."""
    device: Literal["auto", "cpu", "cuda"] = "auto"
    """Where to compute (auto: CUDA when available)."""
    data: Path | None = None
    """Override the scene folder recorded in the config (e.g. the run was made on another machine)."""

    def load_run(self) -> LoadedRun:
        return load_run(self.load_config, config_registry(), self.checkpoint, self.device, self.data)
