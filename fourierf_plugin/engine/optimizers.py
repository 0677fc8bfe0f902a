"""AdamW over the model's parameter groups, restarted at every structural change, lr a function of the step."""

from __future__ import annotations

from dataclasses import dataclass

import torch
from torch import nn

from fourierf_plugin.field_components.schedules import lr_scale_at


@dataclass
class OptimizerConfig:
    lr_grids: float = 0.02
    """Learning rate of the grid factors."""
    lr_networks: float = 1e-3
    """Learning rate of the appearance basis and decoder."""
    betas: tuple[float, float] = (0.9, 0.98)
    """AdamW betas (paper: 0.9, 0.98)."""
    weight_decay: float = 0.2
    """AdamW weight decay (paper: 0.2 for synthetic scenes, 'key to removing floaters'; 0 for real scenes)."""
    lr_decay_ratio: float = 0.1
    """Learning rate after a full run without restarts, relative to the initial one (TensoRF: 0.1; 1.0 = none)."""


def build_optimizer(config: OptimizerConfig, groups: dict[str, list[nn.Parameter]]) -> torch.optim.AdamW:
    """AdamW with the fused kernel: one pass over the ~5M grid values instead of several (5x faster on CPU)."""
    lrs = {"grids": config.lr_grids, "networks": config.lr_networks}
    return torch.optim.AdamW(
        [{"params": params, "lr": lrs[name], "initial_lr": lrs[name], "name": name} for name, params in groups.items()],
        betas=config.betas,
        weight_decay=config.weight_decay,
        fused=True,
    )


def set_learning_rates(
    optimizer: torch.optim.Optimizer, config: OptimizerConfig, step: int, reset_steps: list[int], max_iters: int
) -> float:
    """Apply the lr schedule for ``step``; returns the scale used."""
    scale = lr_scale_at(step, reset_steps, config.lr_decay_ratio, max_iters)
    for group in optimizer.param_groups:
        group["lr"] = group["initial_lr"] * scale
    return scale
