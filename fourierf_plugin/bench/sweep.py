"""A sweep spec (methods × knob values) expanded into independent run specs.

Why a flat list of frozen specs: every run is independent, so the same list can be executed by a local process pool
or a cluster, skipped on resume by its key, and reported from its recorded knob values alone.
"""

from __future__ import annotations

import itertools
import math
from dataclasses import asdict, dataclass, replace
from typing import Literal

from fourierf_plugin.method_configs import all_methods
from fourierf_plugin.utils.errors import fail

KNOBS = ("iters", "downscale", "grid_voxels", "step_ratio", "batch_size", "f0", "ramp_fraction")
"""The knobs that trade accuracy for time, in the order they appear in keys, tables and the CSV."""
REPORT_FRACTIONS = (0.25, 0.5, 1.0)
"""Budget fractions the report quotes; they are always evaluated when a run has 4 or more eval points."""
MIN_ITERS = 10
FINAL_TAIL = 0.2
"""The report's final phase of training: the last 20% of the steps (the grid is at full size, the band open)."""
ProfileMode = Literal["first", "none", "all"]


@dataclass(frozen=True)
class RunSpec:
    """One training run: a method and one value of every knob.

    ``f0`` / ``ramp_fraction`` are None for methods without the Fourier curriculum (they would change nothing);
    ``downscale`` None keeps the parser's default.
    """

    method: str
    iters: int
    downscale: int | None
    grid_voxels: int
    init_voxels: int
    step_ratio: float
    batch_size: int
    f0: float | None
    ramp_fraction: float | None
    seed: int
    eval_points: int
    profile_phases: bool = False

    @property
    def key(self) -> str:
        """The training identity (a path-safe name); eval points and profiling do not change what is trained."""
        parts = [
            self.method,
            f"it{self.iters}",
            f"ds{self.downscale if self.downscale is not None else 'def'}",
            f"g{voxels_label(self.grid_voxels)}",
            f"sr{self.step_ratio:g}",
            f"b{self.batch_size}",
            f"f0{_opt(self.f0)}",
            f"r{_opt(self.ramp_fraction)}",
            f"s{self.seed}",
        ]
        return "_".join(parts)

    def eval_steps(self) -> tuple[int, ...]:
        return eval_steps(self.iters, self.eval_points)

    def steps_per_save(self) -> int:
        """The largest checkpoint interval that still lands on every evaluation step."""
        return math.gcd(*self.eval_steps())

    def log_every(self) -> int:
        """Log at every checkpoint and at 80% of the budget, where the report's final-phase window starts."""
        return math.gcd(self.steps_per_save(), max(1, round((1.0 - FINAL_TAIL) * self.iters)))

    def knobs(self) -> dict[str, object]:
        return {k: getattr(self, k) for k in KNOBS}

    def delta_per_iteration(self) -> float | None:
        """The paper's Δ: how much the kept share of the spectrum grows per iteration, (1 - f0) / ramp length."""
        if self.f0 is None or self.ramp_fraction is None:
            return None
        ramp = round(self.ramp_fraction * self.iters)
        return math.inf if ramp <= 0 else (1.0 - self.f0) / ramp

    def train_args(self) -> list[str]:
        """The ``fourierf-train`` flags that set this run's knobs (data, output and parser flags come elsewhere)."""
        args = [
            self.method,
            "--max-num-iterations", str(self.iters),
            "--seed", str(self.seed),
            "--steps-per-save", str(self.steps_per_save()),
            "--log-every", str(self.log_every()),
            "--keep-checkpoints", "0",
            "--pipeline.datamanager.rays-per-batch", str(self.batch_size),
            "--pipeline.model.field.n-voxels-init", str(self.init_voxels),
            "--pipeline.model.field.n-voxels-final", str(self.grid_voxels),
            "--pipeline.model.step-ratio", repr(self.step_ratio),
        ]  # fmt: skip
        if self.f0 is not None:
            args += ["--pipeline.model.fourier.f0-density", repr(self.f0)]
            args += ["--pipeline.model.fourier.f0-color", repr(self.f0)]
        if self.ramp_fraction is not None:
            args += ["--pipeline.model.fourier.ramp-fraction", repr(self.ramp_fraction)]
        return args

    def as_dict(self) -> dict:
        return asdict(self)


def _opt(value: float | None) -> str:
    return "na" if value is None else f"{value:g}"


def voxels_label(n: int) -> str:
    """``128`` for 128³, else the raw count with a ``v`` (keys and tables stay short)."""
    side = round(n ** (1 / 3))
    return str(side) if side**3 == n else f"{n}v"


def eval_steps(iters: int, points: int) -> tuple[int, ...]:
    """Every ``1/points`` of the budget, plus the quoted 25% and 50% when there are enough points to care."""
    steps = {max(1, round(k * iters / points)) for k in range(1, points + 1)}
    if points >= 4:
        steps |= {max(1, round(f * iters)) for f in REPORT_FRACTIONS}
    return tuple(sorted(steps))


@dataclass(frozen=True)
class SweepSpec:
    """Methods × every combination of knob values (None as a knob value: the method's own default)."""

    methods: tuple[str, ...]
    iters: tuple[int, ...] = (800,)
    downscale: tuple[int | None, ...] = (None,)
    grid_voxels: tuple[int, ...] = (128**3,)
    init_voxels: int = 64**3
    step_ratio: tuple[float, ...] = (0.5,)
    batch_size: tuple[int, ...] = (1024,)
    f0: tuple[float | None, ...] = (None,)
    ramp_fraction: tuple[float | None, ...] = (None,)
    seeds: tuple[int, ...] = (20211202,)
    eval_points: int = 10


def fourier_defaults(method: str) -> tuple[float, float] | None:
    """(f0, ramp_fraction) of a method preset, or None when its curriculum is off (the TensoRF baselines)."""
    fourier = all_methods[method].pipeline.model.fourier
    return (fourier.f0_density, fourier.ramp_fraction) if fourier.enabled else None


def known_methods() -> list[str]:
    return sorted(all_methods)


def validate(spec: SweepSpec) -> None:
    """Every bad sweep is a UserError naming the option."""
    if not spec.methods:
        fail("no methods to run (--methods is empty)", f"pass one or more of: {', '.join(known_methods())}")
    unknown = [m for m in spec.methods if m not in known_methods()]
    if unknown:
        fail(f"unknown method(s) {', '.join(unknown)} in --methods", f"choose from: {', '.join(known_methods())}")
    for name in ("iters", "downscale", "grid_voxels", "step_ratio", "batch_size", "f0", "ramp_fraction", "seeds"):
        if not getattr(spec, name):
            flag = "--" + name.replace("_", "-")
            fail(f"the sweep over {flag} is empty", f"pass at least one value to {flag} (or leave it out)")
    small = [i for i in spec.iters if i < max(MIN_ITERS, spec.eval_points)]
    if small:
        fail(
            f"--iters {small} is too small: a run needs at least {max(MIN_ITERS, spec.eval_points)} iterations "
            f"to be evaluated at {spec.eval_points} points along its budget",
            f"pass --iters of at least {max(MIN_ITERS, spec.eval_points)} (or fewer --eval-points)",
        )
    _check(spec.eval_points >= 1, "--eval-points", spec.eval_points, "at least 1")
    _check(spec.init_voxels >= 8, "--init-voxels", spec.init_voxels, "at least 8 (2³)")
    for d in spec.downscale:
        _check(d is None or d >= 1, "--downscale", d, "an integer of at least 1")
    for g in spec.grid_voxels:
        _check(g >= 8, "--grid-voxels", g, "at least 8 (2³)")
    for s in spec.step_ratio:
        _check(s > 0, "--step-ratio", s, "positive")
    for b in spec.batch_size:
        _check(b >= 1, "--batch-size", b, "at least 1")
    for f in spec.f0:
        _check(f is None or 0.0 <= f <= 1.0, "--f0", f, "within [0, 1]")
    for r in spec.ramp_fraction:
        _check(r is None or 0.0 <= r <= 1.0, "--ramp-fraction / --delta-values", r, "within [0, 1]")


def _check(ok: bool, flag: str, value: object, want: str) -> None:
    if not ok:
        fail(f"{flag} {value} is not valid: it must be {want}", f"pass {flag} values that are {want}")


def expand(spec: SweepSpec) -> list[RunSpec]:
    """Validated runs in a stable order (method-major); duplicates (e.g. f0 given to a baseline) appear once."""
    validate(spec)
    runs: list[RunSpec] = []
    for method in spec.methods:
        defaults = fourier_defaults(method)
        grid = itertools.product(
            spec.iters,
            spec.downscale,
            spec.grid_voxels,
            spec.step_ratio,
            spec.batch_size,
            spec.f0,
            spec.ramp_fraction,
            spec.seeds,
        )
        for iters, down, voxels, ratio, batch, f0, ramp, seed in grid:
            if defaults is None:
                f0, ramp = None, None
            else:
                f0 = defaults[0] if f0 is None else f0
                ramp = defaults[1] if ramp is None else ramp
            runs.append(
                RunSpec(
                    method=method,
                    iters=iters,
                    downscale=down,
                    grid_voxels=voxels,
                    init_voxels=min(spec.init_voxels, voxels),
                    step_ratio=ratio,
                    batch_size=batch,
                    f0=f0,
                    ramp_fraction=ramp,
                    seed=seed,
                    eval_points=spec.eval_points,
                )
            )
    return merge(runs)


def merge(runs: list[RunSpec]) -> list[RunSpec]:
    """One run per key, keeping the first position; a run asked for twice keeps the most eval points."""
    merged: dict[str, RunSpec] = {}
    for run in runs:
        seen = merged.get(run.key)
        if seen is None:
            merged[run.key] = run
        else:
            merged[run.key] = replace(
                seen,
                eval_points=max(seen.eval_points, run.eval_points),
                profile_phases=seen.profile_phases or run.profile_phases,
            )
    return list(merged.values())


def designate_profiled(runs: list[RunSpec], mode: ProfileMode) -> list[RunSpec]:
    """Mark the runs that record a per-phase time breakdown: the first of each method, none, or all."""
    if mode == "all":
        return [replace(r, profile_phases=True) for r in runs]
    if mode == "none":
        return [replace(r, profile_phases=False) for r in runs]
    seen: set[str] = set()
    out = []
    for run in runs:
        out.append(replace(run, profile_phases=run.method not in seen))
        seen.add(run.method)
    return out
