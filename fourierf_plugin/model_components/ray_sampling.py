"""Ray–box intersection and fixed-step sampling (TensoRF's marcher), as pure functions."""

from __future__ import annotations

import torch
from torch import Tensor

_MIN_DIR = 1e-6


def ray_aabb_intersect(origins: Tensor, directions: Tensor, aabb: Tensor) -> tuple[Tensor, Tensor]:
    """Entry and exit ray parameters [R] of the slab test; a ray misses when ``t_max <= t_min``.

    Zero direction components are replaced by 1e-6 (as in TensoRF) so axis-parallel rays stay finite.
    """
    safe = torch.where(directions.abs() < _MIN_DIR, torch.full_like(directions, _MIN_DIR), directions)
    t0 = (aabb[0] - origins) / safe
    t1 = (aabb[1] - origins) / safe
    t_min = torch.minimum(t0, t1).amax(dim=-1)
    t_max = torch.maximum(t0, t1).amin(dim=-1)
    return t_min, t_max


def ray_box_span(origins: Tensor, directions: Tensor, aabb: Tensor, near: float, far: float) -> tuple[Tensor, Tensor]:
    """Where marching starts (box entry clamped to [near, far]) and where the box ends, both [R]."""
    t_min, t_max = ray_aabb_intersect(origins, directions, aabb)
    start = t_min.clamp(min=near, max=far)
    return start, t_max


def step_samples(start: Tensor, step: float, num_samples: int, jitter: Tensor | None = None) -> Tensor:
    """Ray parameters [R, N]: ``start + step * (k + u)`` with one ``u`` per ray (training) or u = 0 (eval)."""
    k = torch.arange(num_samples, device=start.device, dtype=start.dtype)
    offsets = k.unsqueeze(0) if jitter is None else k.unsqueeze(0) + jitter.unsqueeze(-1)
    return start.unsqueeze(-1) + step * offsets


def sample_deltas(t: Tensor) -> Tensor:
    """Interval lengths [R, N]: differences of consecutive samples, the last one 0 (TensoRF convention)."""
    return torch.cat([t[:, 1:] - t[:, :-1], torch.zeros_like(t[:, :1])], dim=-1)
