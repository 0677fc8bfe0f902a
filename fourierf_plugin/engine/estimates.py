"""What a run will cost, printed before it starts: training time on a CPU and the size of its checkpoints."""

from __future__ import annotations

from typing import Any

from fourierf_plugin.engine.option_checks import grid_values
from fourierf_plugin.utils.console import format_duration

SECONDS_PER_RAY_STEP = 1.05e-6
"""A CPU iteration's cost per ray and per voxel of the final grid's side, measured on this project's development
machine with 2 threads (P-CPU: ~110 s for 800 iterations of 1024 rays, final grid 128³): an estimate, not a promise."""


def estimate_seconds(config: Any, threads: int) -> float:
    """A CPU run's training time from the measured cost (scaled by the threads it gets)."""
    side = config.pipeline.model.field.n_voxels_final ** (1.0 / 3.0)
    rays = config.pipeline.datamanager.rays_per_batch
    return config.max_num_iterations * rays * side * SECONDS_PER_RAY_STEP * 2.0 / max(1, threads)


def checkpoint_bytes(config: Any, rays: int) -> float:
    """One checkpoint: the final grid's values with AdamW's two moments, the training rays' state, the rest."""
    field = config.pipeline.model.field
    return grid_values(field, field.n_voxels_final) * 4 * 3 + rays * 16 + 1e6


def describe_cost(config: Any, rays: int, threads: int, cpu: bool) -> str:
    """The line printed before training: how long (on a CPU) and how large the run will be."""
    size = checkpoint_bytes(config, rays) / 2**20
    text = f"checkpoints of ~{size:.0f} MB each, the last {config.keep_checkpoints} kept"
    if cpu:
        text += f"; estimated training time ~{format_duration(estimate_seconds(config, threads))} on {threads} threads"
    return text
