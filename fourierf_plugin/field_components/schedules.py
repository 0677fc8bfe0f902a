"""Step schedules of FourieRF/TensoRF as pure functions of the iteration (spec 3.2, 3.6, 4.1).

Keeping them stateless means a resumed run, an evaluation script and the trainer all agree on the cutoff, learning
rate, L1 weight and grid resolution at any step, without replaying the run.

Step convention: ``step`` is the index of the iteration about to run (0-based). An event listed at step ``s``
(an lr reset, the first alpha-mask update) is in effect for iteration ``s`` itself and every later one.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

__all__ = [
    "cutoff_at",
    "eval_samples_per_ray",
    "l1_weight_at",
    "last_reset_at",
    "lr_scale_at",
    "n_to_reso",
    "step_size",
    "steps_from_fractions",
    "train_samples_per_ray",
    "tv_weight_at",
    "voxel_counts",
]

# Slack for floor(E / voxel): (E^3 / 128^3)^(1/3) can come out a hair above 3/128, which would floor 128 to 127.
_RESO_EPS = 1e-6


def _check_step(step: int) -> int:
    if isinstance(step, bool) or int(step) != step or step < 0:
        raise ValueError(f"step must be a non-negative integer, got {step!r}")
    return int(step)


# ------------------------------------------------------------------------------------------------------- cutoff
def cutoff_at(step: int, f0: float, ramp_iters: int, f_final: float = 1.0) -> float:
    """Fourier cutoff at ``step``: linear from ``f0`` at step 0 to ``f_final`` at ``ramp_iters``, then ``f_final``
    (paper, spec 4.1: ``f_final`` = 1, the whole spectrum in the end).

    ``f_final`` < 1 keeps the field band-limited for good (a few-shot prior; the paper's runs open fully).
    ``ramp_iters <= 0`` opens the band at once; ``f0 >= f_final`` never changes (``f0 == 1``: the TensoRF baseline).
    """
    step = _check_step(step)
    f0, f_final = float(f0), float(f_final)
    if not 0.0 <= f0 <= 1.0:  # also rejects NaN
        raise ValueError(f"initial Fourier cutoff f0 must lie in [0, 1], got {f0!r}")
    if not 0.0 < f_final <= 1.0:
        raise ValueError(f"final Fourier cutoff must lie in (0, 1], got {f_final!r}")
    if f0 > f_final:
        raise ValueError(f"initial Fourier cutoff {f0!r} is above the final one {f_final!r}: the band only opens")
    if ramp_iters <= 0 or f0 == f_final:
        return f_final
    return min(f_final, f0 + step * (f_final - f0) / ramp_iters)


# ------------------------------------------------------------------------------------------------ event steps
def steps_from_fractions(fractions: Sequence[float], max_iters: int) -> list[int]:
    """Event steps (alpha-mask updates, upsamples) placed at the same fractions of a run of ``max_iters``.

    Rounds half up, sorts and drops duplicates. A step of 0 or ``max_iters`` would never fire inside the loop, so
    it is an error rather than a silently skipped event.
    """
    steps: set[int] = set()
    for frac in fractions:
        value = float(frac)
        if not math.isfinite(value):
            raise ValueError(f"event fraction must be a finite number in (0, 1), got {frac!r}")
        step = math.floor(value * max_iters + 0.5)
        if not 1 <= step <= max_iters - 1:
            raise ValueError(
                f"event fraction {frac!r} of {max_iters} iterations falls on step {step}, outside [1, {max_iters - 1}]:"
                " use fractions strictly between 0 and 1 that land inside the run"
            )
        steps.add(step)
    return sorted(steps)


def last_reset_at(step: int, reset_steps: Sequence[int]) -> int:
    """The latest reset step ``<= step``, or 0 (the run start) when none has happened yet."""
    step = _check_step(step)
    return max((s for s in reset_steps if s <= step), default=0)


# ----------------------------------------------------------------------------------------- optimisation weights
def lr_scale_at(step: int, reset_steps: Sequence[int], decay_ratio: float, max_iters: int) -> float:
    """Learning-rate multiplier: ``decay_ratio ** (1 / max_iters)`` per iteration, restarted at every reset.

    Without resets the scale reaches ``decay_ratio`` at ``max_iters`` (TensoRF: 0.1; FourieRF: 1.0, no decay).
    """
    step = _check_step(step)
    decay_ratio = float(decay_ratio)
    if not (math.isfinite(decay_ratio) and decay_ratio > 0.0):
        raise ValueError(f"lr decay ratio must be a finite number > 0, got {decay_ratio!r}")
    if max_iters < 1:
        raise ValueError(f"max_iters must be >= 1, got {max_iters!r}")
    if decay_ratio == 1.0:
        return 1.0
    factor = decay_ratio ** (1.0 / max_iters)
    return factor ** (step - last_reset_at(step, reset_steps))


def tv_weight_at(step: int, initial: float, decay_ratio: float, max_iters: int) -> float:
    """TV weight: TensoRF multiplies it by ``decay_ratio ** (1 / max_iters)`` every iteration and never restarts it,
    so it is ``initial · decay_ratio ** (step / max_iters)`` whatever the lr resets."""
    return float(initial) * lr_scale_at(step, (), decay_ratio, max_iters)


def l1_weight_at(step: int, first_mask_step: int | None, initial: float, rest: float) -> float:
    """Density L1 weight: ``initial`` before the first alpha-mask update, ``rest`` from that step on (TensoRF)."""
    step = _check_step(step)
    if first_mask_step is None or step < first_mask_step:
        return float(initial)
    return float(rest)


# ------------------------------------------------------------------------------------------------ resolution
def voxel_counts(n_init: int, n_final: int, num_upsamples: int) -> list[int]:
    """Voxel totals after each upsample, log-spaced from ``n_init`` to ``n_final`` (spec 3.2).

    Computed in float64: TensoRF's float32 version gives 26999994 for 300^3; here the last entry is ``n_final``.
    """
    if n_init < 1 or n_final < 1:
        raise ValueError(f"voxel counts must be >= 1, got n_init={n_init!r}, n_final={n_final!r}")
    if num_upsamples < 0:
        raise ValueError(f"number of upsamples must be >= 0, got {num_upsamples!r}")
    if num_upsamples == 0:
        return []
    logs = np.linspace(math.log(n_init), math.log(n_final), num_upsamples + 1, dtype=np.float64)
    counts = [round(float(v)) for v in np.exp(logs)[1:]]
    counts[-1] = int(n_final)  # exact by construction; pinned so no platform's exp/log can drift it
    return counts


def n_to_reso(n_voxels: int, aabb_size: Sequence[float]) -> list[int]:
    """Per-axis resolution with about ``n_voxels`` cubic voxels in a box of edge lengths ``aabb_size``.

    ``floor(E / voxel)`` with a tiny slack so float error cannot turn 128 into 127; at least 2 per axis so the
    ``align_corners=True`` grids keep a non-zero voxel size.
    """
    sizes = [float(e) for e in aabb_size]
    if n_voxels < 1:
        raise ValueError(f"voxel count must be >= 1, got {n_voxels!r}")
    if not sizes or not all(math.isfinite(e) and e > 0.0 for e in sizes):
        raise ValueError(f"AABB edge lengths must be finite and > 0, got {list(aabb_size)!r}")
    voxel = (math.prod(sizes) / n_voxels) ** (1.0 / len(sizes))
    return [max(2, math.floor(e / voxel + _RESO_EPS)) for e in sizes]


def step_size(aabb_size: Sequence[float], reso: Sequence[int], step_ratio: float = 0.5) -> float:
    """Ray-marching step: ``step_ratio`` times the mean voxel edge ``E / (reso - 1)`` (align_corners grids)."""
    if len(aabb_size) != len(reso):
        raise ValueError(f"aabb_size and reso need the same length, got {len(aabb_size)} and {len(reso)}")
    if any(r < 2 for r in reso):
        raise ValueError(f"every grid resolution must be >= 2, got {list(reso)!r}")
    units = [float(e) / (int(r) - 1) for e, r in zip(aabb_size, reso, strict=True)]
    return step_ratio * sum(units) / len(units)


def train_samples_per_ray(reso: Sequence[int], step_ratio: float = 0.5) -> int:
    """Samples per training ray, TensoRF's ``cal_n_samples``: ``int(||reso|| / step_ratio)``."""
    return int(math.hypot(*(float(r) for r in reso)) / step_ratio)


def eval_samples_per_ray(aabb_size: Sequence[float], step: float) -> int:
    """Samples per evaluation ray: enough steps to cross the box diagonal, ``int(||E|| / step) + 1``."""
    if not (math.isfinite(step) and step > 0.0):
        raise ValueError(f"ray-marching step must be a finite number > 0, got {step!r}")
    return int(math.hypot(*(float(e) for e in aabb_size)) / step) + 1
