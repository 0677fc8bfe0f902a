"""Which trained run a command works on: the options ``fourierf-eval``, ``fourierf-render`` and ``fourierf-export``
share, and the one way they load it."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Literal

import torch

from fourierf_plugin.engine.loading import LoadedRun, load_run, run_dir_of
from fourierf_plugin.method_configs import config_registry
from fourierf_plugin.utils.console import cpu_threads_note, get_console
from fourierf_plugin.utils.errors import fail


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
    threads: int | None = None
    """CPU threads for torch (default: the cores torch sees); fewer leaves room for other jobs on the machine."""
    force_checkpoint: bool = False
    """Accept a --checkpoint from outside this run's checkpoints/ folder (another run's weights)."""

    def load_run(self) -> LoadedRun:
        if self.threads is not None:
            if self.threads < 1:
                fail(f"--threads {self.threads} must be at least 1", "pass e.g. --threads 2, or omit it")
            torch.set_num_threads(self.threads)
        get_console().print(cpu_threads_note(torch.get_num_threads()))
        if self.checkpoint is not None and Path(self.checkpoint).exists() and not self.force_checkpoint:
            own = run_dir_of(Path(self.load_config)) / "checkpoints"
            if Path(self.checkpoint).resolve().parent != own.resolve():
                fail(
                    f"--checkpoint {self.checkpoint} is not one of this run's checkpoints (they are in {own})",
                    "pass a checkpoint of the run given by --load-config, or add --force-checkpoint to use "
                    "another run's weights with this config",
                )
        return load_run(self.load_config, config_registry(), self.checkpoint, self.device, self.data)
