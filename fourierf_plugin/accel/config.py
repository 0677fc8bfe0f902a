"""Every speed setting in one place: ``--pipeline.model.accel.*``. None of them changes what is computed beyond
float rounding, except ``early_stop_transmittance`` (renders skip what lies behind a nearly opaque ray)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

import torch


@dataclass
class AccelConfig:
    backend: Literal["accelerated", "reference-grid-ops"] = "accelerated"
    """The field's grid operations: accelerated, their fast forms (``fourierf_plugin.accel``); reference-grid-ops, the
    plain ones (rfft filters, grid_sample lookups, autograd), slower, for reading and checking. Only the grid
    operations: early stop, the GPU paths and ZeroRF's culling have their own switches (``early_stop_transmittance``
    0, ``gpu_paths`` False, ``cull_weight_threshold`` 0)."""
    dense_train_max_vertices: int = 1 << 22
    """Training reads the density from a dense vertex table, rebuilt differentiably after every filtering, for
    grids up to this many vertices (larger grids read the factors). 0 = never."""
    dense_render_max_mb: float = 512.0
    """Renders read density and appearance from dense vertex tables, each baked when it fits in this many MB.
    0 = never."""
    decoder_precision: Literal["auto", "float32", "bfloat16"] = "auto"
    """Arithmetic of the appearance basis and decoder on CPU (the grids stay float32; other devices use float32).
    auto: bfloat16 for renders on a CPU with native bf16 matmuls (colour error ~1e-3); bfloat16: also in training."""
    checkpoint_above: int = 65536
    """A training batch with more shaded samples than this computes colour in checkpointed chunks, recomputed in
    the backward pass instead of kept (less memory, some time). 0 = never."""
    checkpoint_chunk: int = 32768
    """Shaded samples per checkpointed chunk."""
    render_chunk_rays: int = 2048
    """Rays rendered at once when rendering whole images."""
    early_stop_transmittance: float = 1e-4
    """Renders stop querying a ray once its transmittance is below this (0 = march every sample)."""
    early_stop_segment: int = 128
    """Samples per ray marched between two early-stop checks."""
    gpu_paths: bool | None = None
    """The forms that keep a GPU busy: no host synchronisation inside a training step but one compaction of the shaded
    samples (a fixed sample count, density at every sample, masks and random numbers made on the device, metrics
    read once per log interval), grid_sample lookups and FFT filters. None: on wherever the device is not a CPU;
    True forces them on a CPU (to check them there; slower)."""


def uses_gpu_paths(config: AccelConfig, device: torch.device | str) -> bool:
    """Whether a model on ``device`` takes the GPU forms (``AccelConfig.gpu_paths``)."""
    return config.gpu_paths if config.gpu_paths is not None else torch.device(device).type != "cpu"
