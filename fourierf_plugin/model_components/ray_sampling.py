"""Ray–box intersection and the three samplers (fixed steps through the box, even steps along NDC rays, fixed steps
of the contracted coordinate for unbounded scenes), and the scene contraction, as pure functions."""

from __future__ import annotations

import math
from dataclasses import dataclass

import torch
from torch import Tensor

from fourierf_plugin.model_components.rendering import random_on

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


@dataclass
class RaySamples:
    """Samples along a batch of R rays, N per ray: parameters, interval lengths, points and which lie in the box."""

    t: Tensor  # [R, N] ray parameters
    deltas: Tensor  # [R, N] interval lengths (the last 0)
    points: Tensor  # [R, N, 3]
    inside: Tensor  # [R, N] bool: the sample lies inside the box
    view_directions: Tensor  # [R, 3] unit directions, for view-dependent colour

    @property
    def shape(self) -> tuple[int, int]:
        return self.t.shape[0], self.t.shape[1]


def _points(origins: Tensor, directions: Tensor, t: Tensor) -> Tensor:
    return torch.addcmul(origins.unsqueeze(1), directions.unsqueeze(1), t.unsqueeze(-1))


def box_samples(
    origins: Tensor,
    directions: Tensor,
    aabb: Tensor,
    near: float,
    far: float,
    step: float,
    max_samples: int,
    generator: torch.Generator | None = None,
    fixed_count: bool = False,
) -> RaySamples:
    """TensoRF's marcher: fixed steps from where each (unit-direction) ray enters the box, as many as the longest
    ray needs (at most ``max_samples``; exactly ``max_samples`` when ``fixed_count``, which spares a GPU the read of
    the longest ray, the extra samples lying outside the box); with a ``generator`` each ray is shifted by its own
    random fraction of a step (training), without one the samples sit on the step grid (renders)."""
    num_rays = origins.shape[0]
    start, t_exit = ray_box_span(origins, directions, aabb, near, far)
    if fixed_count:
        num_samples = max(1, max_samples)
    else:
        span = ((t_exit - start) / step).clamp(min=0)
        needed = math.ceil(float(span.max())) + 1 if num_rays else 0
        num_samples = max(1, min(max_samples, needed))
    jitter = random_on(generator, (num_rays,)).to(origins.device) if generator is not None else None
    t = step_samples(start, step, num_samples, jitter)
    return RaySamples(t, sample_deltas(t), _points(origins, directions, t), t < t_exit.unsqueeze(-1), directions)


def ndc_samples(
    origins: Tensor,
    directions: Tensor,
    aabb: Tensor,
    near: float,
    far: float,
    num_samples: int,
    generator: torch.Generator | None = None,
) -> RaySamples:
    """NDC rays: t evenly spaced in [near, far] (= [0, 1]), each sample jittered within its interval when a
    ``generator`` is given; δ is scaled by |d| (NDC directions are not unit)."""
    num_rays, device = origins.shape[0], origins.device
    t = torch.linspace(near, far, num_samples, device=device).expand(num_rays, num_samples)
    if generator is not None:
        jitter = random_on(generator, (num_rays, num_samples)).to(device)
        t = t + jitter * ((far - near) / num_samples)
    points = _points(origins, directions, t)
    inside = ((points >= aabb[0]) & (points <= aabb[1])).all(dim=-1)
    deltas = sample_deltas(t) * directions.norm(dim=-1, keepdim=True)
    return RaySamples(t, deltas, points, inside, directions / directions.norm(dim=-1, keepdim=True))


def contract(points: Tensor) -> Tensor:
    """Scene contraction (mip-NeRF 360, with the L∞ norm as grids use it): the inner cube [-1, 1]³ is kept as it
    is, everything beyond it is squeezed into the shell out to [-2, 2]³, so a grid covers an unbounded scene."""
    norm = points.abs().amax(dim=-1, keepdim=True)
    outside = norm > 1.0
    safe = torch.where(outside, norm, torch.ones_like(norm))
    return torch.where(outside, (2.0 - 1.0 / safe) * (points / safe), points)


def uncontract(points: Tensor) -> Tensor:
    """The inverse of :func:`contract` on (-2, 2)³."""
    norm = points.abs().amax(dim=-1, keepdim=True)
    outside = norm > 1.0
    safe = torch.where(outside, norm, torch.ones_like(norm))
    return torch.where(outside, points / (safe * (2.0 - safe).clamp(min=1e-6)), points)


ARC_TABLE_POINTS = 64
"""Points per segment (inside the inner cube, beyond it) of the table that maps a ray's parameter to its length in
the contracted space."""


def _table_t(index: Tensor, t_exit: Tensor, near: float, far: float) -> Tensor:
    """Ray parameter at a (fractional) table index: linear from ``near`` to the inner cube's exit over the first
    ``ARC_TABLE_POINTS`` entries, linear in disparity from there to ``far`` over the next ``ARC_TABLE_POINTS``."""
    k = float(ARC_TABLE_POINTS)
    u = (index / k).clamp(max=1.0)
    v = ((index - k) / k).clamp(min=0.0, max=1.0)
    linear = near + (t_exit - near) * u
    beyond = t_exit / (1.0 - v * (1.0 - t_exit / far))
    return torch.where(index < k, linear, beyond)


def _inner_exit(origins: Tensor, directions: Tensor, near: float, far: float) -> Tensor:
    inner = torch.tensor([[-1.0] * 3, [1.0] * 3], device=origins.device, dtype=origins.dtype)
    return ray_aabb_intersect(origins, directions, inner)[1].clamp(min=near, max=far).unsqueeze(-1)


def contracted_arc_table(origins: Tensor, directions: Tensor, near: float, far: float) -> tuple[Tensor, Tensor, Tensor]:
    """Per ray, ray parameters [R, 2K+1] from ``near`` to ``far`` (``_table_t`` at whole indices), the length of
    the contracted ray up to each, and where the ray leaves the inner cube [R, 1]: what :func:`contracted_samples`
    inverts."""
    t_exit = _inner_exit(origins, directions, near, far)
    index = torch.arange(2 * ARC_TABLE_POINTS + 1, device=origins.device, dtype=origins.dtype)
    t = _table_t(index.expand(origins.shape[0], -1), t_exit, near, far)
    points = contract(_points(origins, directions, t))
    steps = (points[:, 1:] - points[:, :-1]).norm(dim=-1)
    length = torch.cat([torch.zeros_like(t[:, :1]), steps.cumsum(dim=-1)], dim=-1)
    return t, length, t_exit


def contracted_samples(
    origins: Tensor,
    directions: Tensor,
    aabb: Tensor,
    near: float,
    far: float,
    step: float,
    max_samples: int,
    generator: torch.Generator | None = None,
) -> RaySamples:
    """Unbounded scenes: each (unit-direction) ray from ``near`` to ``far`` marched in fixed steps of its length in the
    contracted space (one random shift per ray in training), so samples are as dense in the far shell as in the inner
    cube; the points are the contracted positions the grid (``aabb`` ⊆ [-2, 2]³) covers, the intervals metric ones."""
    num_rays = origins.shape[0]
    table_t, table_length, t_exit = contracted_arc_table(origins, directions, near, far)
    span = table_length[:, -1]
    needed = math.ceil(float(span.max()) / step) + 1 if num_rays else 0
    num_samples = max(1, min(max_samples, needed))
    jitter = random_on(generator, (num_rays,)).to(origins.device) if generator is not None else None
    length = step_samples(torch.zeros_like(span), step, num_samples, jitter)
    within = length < span.unsqueeze(-1)
    length = torch.minimum(length, span.unsqueeze(-1)).contiguous()
    upper = torch.searchsorted(table_length, length, right=True).clamp(1, table_t.shape[1] - 1)
    l0, l1 = table_length.gather(1, upper - 1), table_length.gather(1, upper)
    index = (upper - 1) + (length - l0) / (l1 - l0).clamp(min=1e-12)
    t = _table_t(index, t_exit, near, far)
    points = contract(_points(origins, directions, t))
    inside = within & ((points >= aabb[0]) & (points <= aabb[1])).all(dim=-1)
    return RaySamples(t, sample_deltas(t), points, inside, directions)
