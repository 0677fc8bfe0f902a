"""``--time-budget``: a run sized in wall time rather than iterations.

The budget picks ``max_num_iterations`` before the short-run rules are applied (as if the user had typed it), so the
count it picks decides which rules apply, and every schedule stays a fraction of the run. The cost of an iteration
comes from timing a few real steps of the configured pipeline on a throwaway copy (``measure_first_steps``), scaled
to the whole run by ``estimates.run_shape``; the budget covers the training loop only (setup, this timing and
evaluation come on top). Once it trains, the run plans its length again from its own speed before its first
count-dependent event and after its last, within the counts its short-run rules cover (``LengthPlan``,
``Trainer._replan``).
"""

from __future__ import annotations

import copy
import functools
import math
import re
import sys
import time
from collections.abc import Callable
from dataclasses import dataclass, replace

import torch

from fourierf_plugin.engine.estimates import checkpoint_bytes, mean_rays_per_batch, run_shape, save_seconds
from fourierf_plugin.engine.machine import pick_device, seed_everything
from fourierf_plugin.engine.optimizers import build_optimizer
from fourierf_plugin.engine.trainer import LengthPlan, TrainerConfig, optimisation_step
from fourierf_plugin.method_configs.budget import AtStep, Run, rule_span, rules_for
from fourierf_plugin.utils.console import format_duration
from fourierf_plugin.utils.errors import fail

FLAG = "--time-budget"
EXAMPLES = "90s, 5m, 1.5h or 1h30m"
MARGIN = 0.05
"""The share of the budget left free: the run's shape is an estimate, and the machine's load varies."""
MIN_ITERATIONS = 100
"""The shortest run a budget may pick: below it the schedules' events crowd together and the field barely forms."""
WARMUP_STEPS, TIMED_STEPS = 2, 8
"""Steps of the calibration copy run before timing (allocations, first-call costs) and then timed."""
MAX_ROUNDS = 4
"""Calibrations at most: a count that changes which short-run rules apply is timed again with those rules."""

_DURATION = re.compile(r"(?:(?P<h>\d+(?:\.\d+)?)h)?(?:(?P<m>\d+(?:\.\d+)?)m)?(?:(?P<s>\d+(?:\.\d+)?)s)?")
_UNIT_SECONDS = {"h": 3600.0, "m": 60.0, "s": 1.0}


def parse_duration(text: str) -> float:
    """Seconds in ``text``: hours, minutes and seconds, each optional but in that order (``90s``, ``5m``, ``1.5h``,
    ``1h30m``); anything else, zero included, is a UserError naming ``--time-budget``."""
    match = _DURATION.fullmatch(text.strip().lower())
    if not text.strip() or match is None:
        fail(f"{FLAG} {text!r} is not a duration", f"pass hours, minutes or seconds, e.g. {FLAG} 5m ({EXAMPLES})")
    seconds = sum(float(v) * _UNIT_SECONDS[unit] for unit, v in match.groupdict().items() if v is not None)
    if not seconds > 0:
        fail(f"{FLAG} {text!r} is no time at all", f"pass a positive duration, e.g. {FLAG} 5m ({EXAMPLES})")
    return seconds


@dataclass(frozen=True)
class StepCost:
    """What a run of ``n`` iterations costs: ``n`` iterations at ``seconds_per_iteration`` (the run's average, the
    occupancy updates, upsamples and ray filtering included through ``run_shape``) plus one checkpoint every
    ``steps_per_save`` iterations and one at the end, each ``seconds_per_save``."""

    seconds_per_iteration: float
    seconds_per_save: float = 0.0
    steps_per_save: int = 1000

    def seconds(self, iterations: int) -> float:
        saves = iterations // self.steps_per_save + (iterations % self.steps_per_save != 0)
        return iterations * self.seconds_per_iteration + saves * self.seconds_per_save


def plan_iterations(budget_s: float, cost: StepCost, margin: float = MARGIN, minimum: int = MIN_ITERATIONS) -> int:
    """The most iterations whose ``cost`` fits ``budget_s`` less ``margin`` of it (monotone in the budget); a
    UserError when not even ``minimum`` fits."""
    available = budget_s * (1.0 - margin)
    if cost.seconds(minimum) > available:
        need = cost.seconds(minimum) / (1.0 - margin)
        fail(
            f"{FLAG} {format_duration(budget_s)} is too short for this run: {minimum} iterations, the fewest a budget "
            f"may pick, need about {format_duration(need)} here (~{cost.seconds_per_iteration:.3g} s per iteration)",
            f"pass a longer {FLAG} (at least {format_duration(math.ceil(need))}), or --max-num-iterations N instead",
        )
    low, high = minimum, max(minimum + 1, math.ceil(available / cost.seconds_per_iteration) + 1)
    while cost.seconds(high) <= available:  # the saves only add cost, so this rarely grows
        high *= 2
    while high - low > 1:  # cost(low) fits, cost(high) does not
        middle = (low + high) // 2
        low, high = (middle, high) if cost.seconds(middle) <= available else (low, middle)
    return low


def at_mean_batch(config: TrainerConfig) -> TrainerConfig:
    """``config`` with every batch at its run's mean ray count: a batch that grows along the run (ZeroRF's schedule)
    is then timed at its average rather than at its first, smallest size."""
    manager = config.pipeline.datamanager
    if not manager.rays_per_batch_schedule:
        return config
    timed = copy.deepcopy(config)
    timed.pipeline.datamanager = replace(
        manager, rays_per_batch=round(mean_rays_per_batch(config)), rays_per_batch_schedule=None
    )
    return timed


def measure_first_steps(config: TrainerConfig, warmup: int = WARMUP_STEPS, steps: int = TIMED_STEPS) -> float:
    """Seconds per iteration of ``steps`` real iterations of ``config``'s pipeline (a finished config) at its mean
    batch, after ``warmup`` untimed ones, on a throwaway copy built on the run's device and threads; the trainer
    seeds itself again, so the run it starts afterwards is the same as without this."""
    config = at_mean_batch(config)
    if config.threads is not None:
        torch.set_num_threads(config.threads)
    device = pick_device(config.device)
    pipeline = config.pipeline.setup(
        device=device, max_iters=config.max_num_iterations, generator=seed_everything(config.seed)
    )
    reset_steps = [s + 1 for s in pipeline.model.reset_steps()]
    optimizer = build_optimizer(config.optimizer, pipeline.model.param_groups(), 0, reset_steps)
    started = 0.0
    for step in range(warmup + steps):
        if step == warmup:
            started = time.perf_counter()
        optimizer, metrics, _ = optimisation_step(
            pipeline, optimizer, config.optimizer, step, reset_steps, config.max_num_iterations
        )
        pipeline.read_metrics(metrics)  # waits for the device
    return (time.perf_counter() - started) / steps


def run_cost(config: TrainerConfig, first_steps_s: float) -> StepCost:
    """The cost of ``config``'s run from its first steps' measured seconds per iteration."""
    rays = config.pipeline.datamanager.rays_per_batch  # the checkpoint's ray state is small beside its grid
    return StepCost(
        first_steps_s * run_shape(config), save_seconds(checkpoint_bytes(config, rays)), config.steps_per_save
    )


@dataclass(frozen=True)
class Plan:
    budget_s: float
    iterations: int
    cost: StepCost
    calibration_s: float

    @property
    def planned_s(self) -> float:
        return self.cost.seconds(self.iterations)

    def describe(self, text: str) -> str:
        return (
            f"time budget {text} ({format_duration(self.budget_s)}): ~{self.cost.seconds_per_iteration:.3g} s per "
            f"iteration (timed over {TIMED_STEPS} steps of this run's pipeline, scaled to the whole run), so "
            f"max_num_iterations={self.iterations}, planned training time {format_duration(self.planned_s)}; the "
            f"budget covers training only: setup, this timing ({format_duration(self.calibration_s)}) and evaluation "
            "are not included; the run plans its length again from its own speed before its first event and after "
            "its last, and should its iterations still cost more than planned, training stops and saves at the budget"
        )


def plan_run(
    config: TrainerConfig,
    finish: Callable[[TrainerConfig], object],
    background: str = "white",
    measure: Callable[[TrainerConfig], float] | None = None,
) -> Plan:
    """The plan for ``config``'s ``--time-budget``: ``finish`` completes a copy set to a trial count the way
    ``finalize`` completes the run (short-run rules, scene effects); the copy is timed with ``measure`` (default
    ``measure_first_steps``). A count is only planned from the cost of a copy under the same short-run rules (a rule
    can change an iteration's cost), so a count that falls under other rules is timed again under those; where the
    rules' ranges and the costs disagree, the plan is the longest run that fits under rules that were timed."""
    assert config.time_budget is not None
    budget_s = parse_duration(config.time_budget)
    measure = measure or measure_first_steps
    started = time.perf_counter()
    iterations, timed_spans, fits = config.max_num_iterations, set(), []
    for _ in range(MAX_ROUNDS):
        trial = copy.deepcopy(config)
        trial.max_num_iterations = iterations
        finish(trial)
        cost = run_cost(trial, measure(trial))
        low, high = _span(trial, iterations, background)
        timed_spans.add((low, high))
        planned = plan_iterations(budget_s, cost)
        if planned >= low:  # the longest count under these rules that fits
            fits.append((min(planned, high - 1), cost))
        if low <= planned < high or _span(trial, planned, background) in timed_spans:
            break
        iterations = planned
    if not fits:
        fail(
            f"{FLAG} {config.time_budget}: no run under the short-run rules it was timed with fits the budget",
            f"pass a longer {FLAG}, or --max-num-iterations N instead",
        )
    planned, cost = max(fits, key=lambda fit: fit[0])
    return Plan(budget_s, planned, cost, time.perf_counter() - started)


def _span(config: TrainerConfig, iterations: int, background: str) -> tuple[int, int]:
    """The counts around ``iterations`` that ``config`` would run under the same short-run rules."""
    if not config.budget_rule:
        return 0, sys.maxsize
    return rule_span(replace(Run.of(config, background), iterations=iterations))


def apply_time_budget(
    config: TrainerConfig, finish: Callable[[TrainerConfig], object], background: str = "white"
) -> list[str]:
    """Set ``config.max_num_iterations`` (and the planned seconds the trainer compares with the actual ones at the
    end, and what it plans the length again with once it trains) from its ``--time-budget``; the note that says so."""
    if config.time_budget is None:
        return []
    plan = plan_run(config, finish, background)
    config.max_num_iterations = plan.iterations
    config.planned_train_seconds = plan.planned_s
    config.train_deadline_seconds = plan.budget_s - plan.cost.seconds_per_save  # the last checkpoint inside it
    finished = copy.deepcopy(config)
    finish(finished)
    low, high = _span(config, plan.iterations, background)
    config.length_plan = LengthPlan(
        plan.budget_s * (1.0 - MARGIN),
        plan.cost.seconds_per_save,
        max(low, MIN_ITERATIONS),
        high,
        pinned_steps(finished, background),
    )
    return [plan.describe(config.time_budget)]


def pinned_steps(config: TrainerConfig, background: str) -> tuple[tuple[str, int, int], ...]:
    """The settings of ``config`` (a finished one) that a short-run rule placed at a fixed step (``AtStep``), as the
    trainer's length plan keeps them: (config path, item of a tuple or -1, step); a value the user set is not one."""
    if not config.budget_rule:
        return ()
    pins = []
    for rule in rules_for(Run.of(config, background)):
        resolved = rule.values(config.max_num_iterations)
        for path, value in rule.settings.items():
            if functools.reduce(getattr, path.split("."), config) != resolved[path]:
                continue
            items = enumerate(value) if isinstance(value, tuple) else [(-1, value)]
            pins += [(path, index, item.step) for index, item in items if isinstance(item, AtStep)]
    return tuple(pins)
