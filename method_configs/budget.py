"""The short-run defaults: the paper's values are tuned for its 10k iterations, and a shorter run gets other ones.

Each default is one row of ``RULES``: which runs it applies to (by what they are: the scene kind, whether the field
has a curriculum, its factors, the declared background, a half-open range of iteration counts), what it sets and why
in a line; ``docs/defaults.md`` holds each row's evidence under the row's name. The rows were chosen on VM fields; a
CP field gets every row whose mechanism does not depend on the factors' shape (the optimiser, the curriculum, the
background, the regulariser, the schedule) and not those that do (component counts, the TV weights on the planes).
A generated field (ZeroRF) and an MLP (FreeNeRF) match no row: the paper compares them at their published settings.

A flag the user typed always wins; ``--budget-rule False`` (``fourierf-vm-paper`` is ``fourierf-vm`` with it off)
keeps the preset's values at any budget.
"""

from __future__ import annotations

import sys
from collections.abc import Mapping
from dataclasses import dataclass, replace
from types import MappingProxyType
from typing import Any

from fourierf_plugin.engine.trainer import TrainerConfig
from fourierf_plugin.method_configs.scene_presets import apply_settings, generated_field
from fourierf_plugin.models.freenerf import mlp_config

PAPER_ITERATIONS = 10_000
"""The paper's budget: runs this long or longer keep the paper's values."""

OBJECT, FORWARD_FACING = "object", "forward-facing"
TRAINED_FIELDS = ("vm", "cp")
"""The fields a row may name: TensoRF's trained factors (a generated field, ``"generated"``, and an MLP, ``"mlp"``,
match no row)."""


@dataclass(frozen=True)
class AtStep:
    """A schedule fraction that puts an event at a fixed step of the run, whatever its length."""

    step: int

    def fraction(self, iterations: int) -> float:
        return round(self.step / iterations, 4)


def field_kind(config: TrainerConfig) -> str:
    """What a run's field is, for the rows: ``generated`` (ZeroRF), ``mlp`` (FreeNeRF) or the factors' ``vm``/``cp``."""
    model = config.pipeline.model
    if generated_field(config):
        return "generated"
    return "mlp" if mlp_config(model) is not None else model.field.decomposition


@dataclass(frozen=True)
class Run:
    """What a row matches on: the run's properties, never its preset's name."""

    scene: str
    """``object`` or ``forward-facing``: the scene preset in force (the parser's declaration unless
    ``--scene-preset`` forces one), whose values the rows build on."""
    curriculum: bool
    """Whether the field has FourieRF's frequency curriculum (``pipeline.model.fourier.enabled``)."""
    field: str
    """``vm``, ``cp``, ``generated`` or ``mlp`` (FreeNeRF's network)."""
    iterations: int
    background: str
    """The background the scene declares."""

    @classmethod
    def of(cls, config: TrainerConfig, background: str) -> Run:
        model = config.pipeline.model
        return cls(
            scene=OBJECT if config.scene_preset == "synthetic" else FORWARD_FACING,
            curriculum=model.fourier.enabled,
            field=field_kind(config),
            iterations=config.max_num_iterations,
            background=background,
        )


@dataclass(frozen=True)
class Rule:
    """One short-run default: what it sets, for which runs, and why."""

    name: str
    scene: str
    iterations: tuple[int, int]
    """Half-open: ``lo <= iterations < hi``."""
    settings: Mapping[str, Any]
    """Config path -> value; an ``AtStep`` (also inside a tuple) becomes the run's fraction for that step."""
    reason: str
    curriculum: bool | None = None
    """Only runs with (True) or without (False) the curriculum; None: both."""
    fields: tuple[str, ...] = TRAINED_FIELDS
    background: str | None = None
    """Only scenes that declare this background; None: any."""

    def __post_init__(self) -> None:
        object.__setattr__(self, "settings", MappingProxyType(dict(self.settings)))

    @property
    def anchor(self) -> str:
        return f"docs/defaults.md#{self.name}"

    def applies(self, run: Run) -> bool:
        lo, hi = self.iterations
        return (
            run.scene == self.scene
            and lo <= run.iterations < hi
            and self.curriculum in (None, run.curriculum)
            and run.field in self.fields
            and self.background in (None, run.background)
        )

    def values(self, iterations: int) -> dict[str, Any]:
        """The settings for a run of ``iterations``."""

        def resolve(value: Any) -> Any:
            if isinstance(value, AtStep):
                return value.fraction(iterations)
            if isinstance(value, tuple):
                return tuple(resolve(v) for v in value)
            return value

        return {path: resolve(value) for path, value in self.settings.items()}


def _tv(weight: float) -> dict[str, float]:
    return {"pipeline.model.tv_weight_density": weight, "pipeline.model.tv_weight_appearance": weight}


SHORT = (0, PAPER_ITERATIONS)
"""Every run shorter than the paper's."""
MEASURED = (800, PAPER_ITERATIONS)
"""From the CPU default up: rows measured there and not below (tests and previews keep the preset's values)."""
BAND_AT_END = (0, 801)
"""Forward-facing runs whose band opens over the whole run (the real-scene preset's ramp), up to the CPU default."""
BAND_BY_800 = (801, PAPER_ITERATIONS)
"""Forward-facing runs long enough for the band to open by step 800, before the run ends."""

RULES: tuple[Rule, ...] = (
    Rule(
        "object-optimiser", OBJECT, SHORT,
        {"optimizer.weight_decay": 0.0, "optimizer.lr_decay_ratio": 1.0, "optimizer.lr_grids": 0.04},
        "below the paper's budget an object fits better with the official code's optimiser (no weight decay, no lr "
        "decay, so no TV decay) at twice TensoRF's grid lr",
    ),
    Rule(
        "object-tv", OBJECT, SHORT, _tv(4.0),
        "a stronger TV on the planes; VM only: a CP field's TV is on its lines, at another scale",
        fields=("vm",),
    ),
    Rule(
        "object-components", OBJECT, MEASURED,
        {"pipeline.model.field.density_components": (8,) * 3, "pipeline.model.field.appearance_components": (24,) * 3},
        "half TensoRF's VM components fit an object as well, in less time (fewer light a fresh field more slowly, "
        "so not in shorter runs); VM only: CP's counts are of rank-one components",
        fields=("vm",),
    ),
    Rule(
        "object-random-background", OBJECT, MEASURED, {"pipeline.effects.background": "random"},
        "images with alpha: a random training background charges the fog outside the silhouette that white leaves free",
        background="white",
    ),
    Rule(
        "object-narrow-band", OBJECT, (800, 1001),
        {"pipeline.model.fourier.f0_density": 0.05, "pipeline.model.fourier.f0_color": 0.05},
        "a narrow first band fills the object's hull with smooth density for the random background to clear; "
        "longer runs do better with the paper's",
        curriculum=True,
    ),
    Rule(
        "object-ray-entropy", OBJECT, MEASURED, {"pipeline.model.entropy_weight": 0.00003},
        "InfoNeRF's ray entropy charges fog and doubled geometry that no training photo does",
    ),
    Rule(
        "forward-facing-optimiser", FORWARD_FACING, SHORT,
        {"optimizer.lr_grids": 0.08, "pipeline.model.tv_decay_ratio": 1.0},
        "TensoRF's grid lr and decaying TV are tuned for far longer runs: a short one wants a 4x rate, a constant TV",
    ),
    Rule(
        "forward-facing-short-tv", FORWARD_FACING, BAND_AT_END, _tv(6.0),
        "a strong TV on the planes while the band opens over the whole run; VM only, as object-tv",
        fields=("vm",),
    ),
    Rule(
        "forward-facing-tv", FORWARD_FACING, BAND_BY_800, _tv(4.0),
        "a stronger TV on the planes, less than while the band opens over the whole run; VM only, as object-tv",
        fields=("vm",),
    ),
    Rule(
        "forward-facing-image-plane-band", FORWARD_FACING, BAND_AT_END, {"pipeline.model.fourier.density_axes": (0, 1)},
        "while the band opens over the whole run, filter the density across the view only, so a surface's depth can "
        "be sharp early",
        curriculum=True,
    ),
    Rule(
        "forward-facing-early-band", FORWARD_FACING, BAND_BY_800, {"pipeline.model.fourier.ramp_fraction": AtStep(800)},
        "open the band by step 800 rather than at the end of the run",
        curriculum=True,
    ),
    Rule(
        "forward-facing-revive-at-once", FORWARD_FACING, BAND_BY_800, {"pipeline.model.field.revive_patience": 1},
        "where the band opens early, revive a dark ReLU density field at its first dark batch",
    ),
    Rule(
        "forward-facing-late-occupancy", FORWARD_FACING, (800, 2000),
        {"pipeline.model.occupancy_update_fractions": (AtStep(200),)},
        "the one occupancy update waits for step 200, so it cannot prune a field that has not lit yet (from 2000 "
        "iterations on, the preset's 10 % is that late)",
    ),
)  # fmt: skip
"""The short-run defaults, one row each (docs/defaults.md, under each row's name)."""


def rules_for(run: Run) -> list[Rule]:
    """The rows that apply to ``run``, in table order."""
    return [rule for rule in RULES if rule.applies(run)]


def rule_span(run: Run) -> tuple[int, int]:
    """The half-open range of iteration counts around ``run.iterations`` under which the same rows apply to ``run``
    (``sys.maxsize`` where no row bounds it from above)."""
    edges = {
        edge for rule in RULES if rule.applies(replace(run, iterations=rule.iterations[0])) for edge in rule.iterations
    }
    lower = [edge for edge in edges if edge <= run.iterations]
    upper = [edge for edge in edges if edge > run.iterations]
    return max(lower, default=0), min(upper, default=sys.maxsize)


def short_run_settings(run: Run) -> dict[str, Any]:
    """Everything the rows set for ``run`` (config path -> value)."""
    settings: dict[str, Any] = {}
    for rule in rules_for(run):
        settings |= rule.values(run.iterations)
    return settings


def apply_budget_rule(
    config: TrainerConfig,
    pristine: TrainerConfig | None,
    given: frozenset[str] = frozenset(),
    background: str = "white",
) -> list[str]:
    """Set each applying row's values where the user left the preset's (a flag, ``given``, always wins) on a scene that
    declares ``background``; the lines to print: that the run departs from the paper's configuration, then one per
    row (its name, what it set, what it kept)."""
    if not config.budget_rule:
        return []
    run = Run.of(config, background)
    lines, departs = [], False
    for rule in rules_for(run):
        applied, kept = apply_settings(config, pristine, rule.values(run.iterations), given)
        departs |= bool(applied)
        if applied or kept:
            line = f"  {rule.name}: {', '.join(applied) if applied else 'nothing'}"
            lines.append(line + (f" (kept your {', '.join(kept)})" if kept else ""))
    if not departs:
        return []
    header = (
        f"short-run defaults: a run of {run.iterations} iterations (the paper's: {PAPER_ITERATIONS}) departs from "
        "the paper's configuration by the rules below (why: docs/defaults.md); for the paper's, pass "
        "--budget-rule False (fourierf-vm-paper is fourierf-vm with it off)"
    )
    return [header, *lines]
