"""What a run will cost, printed before it starts: training time on a CPU and the size of its checkpoints."""

from __future__ import annotations

import math
from typing import Any

from fourierf_plugin.engine.option_checks import grid_values
from fourierf_plugin.field_components.generator import parameter_count
from fourierf_plugin.utils.console import format_duration

SECONDS_PER_RAY_STEP = 1.05e-6
"""A CPU iteration's cost per ray and per voxel of the final grid's side, measured on this project's development
machine with 2 threads (P-CPU: ~110 s for 800 iterations of 1024 rays, final grid 128³): an estimate, not a promise."""


SECONDS_PER_GENERATED_VALUE = 1.0e-6
"""A zerorf-vm iteration's added cost per value its generators draw (forward and backward, ZeroRF's widths, 2 threads;
measured on the development machine: three 128² canvases of 16 channels, ~0.77 s)."""


def estimate_seconds(config: Any, threads: int) -> float:
    """A CPU run's training time from the measured cost (scaled by the threads it gets)."""
    field = config.pipeline.model.field
    side = field.n_voxels_final ** (1.0 / 3.0)
    rays = config.pipeline.datamanager.rays_per_batch + config.pipeline.model.unseen_rays()
    per_iteration = rays * side * SECONDS_PER_RAY_STEP
    if field.zerorf.enabled:  # a cubic box's canvases: the smallest multiple of 2^levels covering the final grid
        scale = 2**field.zerorf.upsample_levels
        noise = field.zerorf.noise_resolution or math.ceil(side / scale)
        canvas = scale * noise
        per_iteration += 3 * canvas**2 * field.zerorf.feature_channels * SECONDS_PER_GENERATED_VALUE
    return config.max_num_iterations * per_iteration * 2.0 / max(1, threads)


def checkpoint_bytes(config: Any, rays: int) -> float:
    """One checkpoint: the final grid's values with AdamW's two moments, the training rays' state, the rest."""
    field = config.pipeline.model.field
    values = parameter_count(field.zerorf) if field.zerorf.enabled else grid_values(field, field.n_voxels_final)
    return values * 4 * 3 + rays * 16 + 1e6


def describe_cost(config: Any, rays: int, threads: int, cpu: bool) -> str:
    """The line printed before training: how long (on a CPU) and how large the run will be."""
    size = checkpoint_bytes(config, rays) / 2**20
    text = f"checkpoints of ~{size:.0f} MB each, the last {config.keep_checkpoints} kept"
    if cpu:
        text += f"; estimated training time ~{format_duration(estimate_seconds(config, threads))} on {threads} threads"
    return text
