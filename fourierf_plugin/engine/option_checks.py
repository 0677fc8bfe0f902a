"""Range checks of the training options, run before anything is built or written.

Why: tyro checks types only. A nonsense value (``--pipeline.model.fourier.f0-density 1.5``, ``--steps-per-save 0``,
a negative step ratio) otherwise ends in a ValueError or ZeroDivisionError deep inside the first iteration, after a
run directory was made, or worse trains silently on garbage (a negative distance scale). Each rule names the flag,
what it needs and an example, so the message is the fix.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

from fourierf_plugin.field_components.generator import invalid_options
from fourierf_plugin.field_components.schedules import steps_from_fractions
from fourierf_plugin.fields.fourier_tensorf_field import ALL_AXES
from fourierf_plugin.models.freenerf import GRID_ONLY_OPTIONS, mlp_config
from fourierf_plugin.models.zerorf import generator_config
from fourierf_plugin.utils.errors import UserError, fail
from fourierf_plugin.utils.memory import available_memory, check_fits


def _number(value: Any) -> bool:
    return isinstance(value, (int, float)) and not isinstance(value, bool) and math.isfinite(value)


def _integer(value: Any) -> bool:
    return isinstance(value, int) and not isinstance(value, bool)


def at_least(low: float) -> Callable[[Any], bool]:
    return lambda v: _number(v) and v >= low


def positive(v: Any) -> bool:
    return _number(v) and v > 0


def int_at_least(low: int) -> Callable[[Any], bool]:
    return lambda v: _integer(v) and v >= low


def within(low: float, high: float) -> Callable[[Any], bool]:
    return lambda v: _number(v) and low <= v <= high


def each(rule: Callable[[Any], bool]) -> Callable[[Any], bool]:
    return lambda v: isinstance(v, (tuple, list)) and all(rule(x) for x in v)


def optional(rule: Callable[[Any], bool]) -> Callable[[Any], bool]:
    return lambda v: v is None or rule(v)


@dataclass(frozen=True)
class Rule:
    path: str
    """Attribute path in the trainer config; the flag is ``--`` + the path with ``_`` as ``-``."""
    ok: Callable[[Any], bool]
    needs: str
    example: str


_MODEL = "pipeline.model"
_ACCEL = f"{_MODEL}.accel"
RULES: tuple[Rule, ...] = (
    Rule("seed", lambda v: int_at_least(0)(v) and v < 2**63, "an integer in 0..2^63-1", "20211202"),
    Rule("steps_per_save", int_at_least(1), "an integer >= 1", "1000"),
    Rule("log_every", int_at_least(1), "an integer >= 1", "50"),
    Rule("viewer_port", lambda v: int_at_least(1)(v) and v <= 65535, "a TCP port in 1..65535", "7007"),
    Rule("viewer_max_slowdown", within(1e-3, 1.0), "a share of training time in [0.001, 1]", "0.03"),
    Rule("vis_image_every", int_at_least(1), "an integer >= 1", "500"),
    Rule("threads", optional(int_at_least(1)), "an integer >= 1 (or omitted for torch's default)", "2"),
    Rule("pipeline.datamanager.rays_per_batch", int_at_least(1), "an integer >= 1", "4096"),
    Rule(f"{_MODEL}.fourier.f0_density", within(0.0, 1.0), "a cutoff in [0, 1] (0 keeps only DC, 1 all)", "0.3"),
    Rule(f"{_MODEL}.fourier.f0_color", within(0.0, 1.0), "a cutoff in [0, 1] (0 keeps only DC, 1 all)", "0.3"),
    Rule(f"{_MODEL}.fourier.f_final", within(1e-3, 1.0), "a cutoff in (0, 1] (1: the whole spectrum)", "1.0"),
    Rule(
        f"{_MODEL}.fourier.f_final_color",
        optional(within(1e-3, 1.0)),
        "a cutoff in (0, 1] (or omitted: the final cutoff's)",
        "1.0",
    ),
    Rule(f"{_MODEL}.fourier.ramp_fraction", at_least(0.0), "a fraction of the run >= 0", "0.2"),
    Rule(f"{_MODEL}.fourier.plane_leakage", at_least(0.0), "a weight >= 0", "0"),
    Rule(
        f"{_MODEL}.fourier.density_axes",
        lambda v: isinstance(v, (tuple, list)) and 0 < len(v) == len(set(v)) and all(x in ALL_AXES for x in v),
        "one or more distinct world axes among 0 1 2 (x y z)",
        "0 1",
    ),
    Rule(f"{_MODEL}.step_ratio", positive, "a number of voxels > 0", "0.5"),
    Rule(f"{_MODEL}.distance_scale", positive, "a number > 0", "25"),
    Rule(f"{_MODEL}.occupancy_threshold", within(0.0, 1.0), "an alpha in [0, 1]", "1e-4"),
    Rule(f"{_MODEL}.weight_threshold", within(0.0, 1.0), "a weight in [0, 1]", "1e-4"),
    Rule(f"{_MODEL}.tv_weight_density", at_least(0.0), "a weight >= 0", "1.0"),
    Rule(f"{_MODEL}.tv_weight_appearance", at_least(0.0), "a weight >= 0", "1.0"),
    Rule(f"{_MODEL}.l1_weight_initial", at_least(0.0), "a weight >= 0", "8e-5"),
    Rule(f"{_MODEL}.l1_weight_rest", at_least(0.0), "a weight >= 0", "4e-5"),
    Rule(f"{_MODEL}.tv_decay_ratio", optional(positive), "a ratio > 0 (1 = no decay; omitted = the lr's)", "0.1"),
    Rule(f"{_MODEL}.occlusion_weight", at_least(0.0), "a weight >= 0", "0.01"),
    Rule(f"{_MODEL}.depth_smoothness_weight", at_least(0.0), "a weight >= 0 (0 = off)", "0.1"),
    Rule(f"{_MODEL}.distortion_weight", at_least(0.0), "a weight >= 0 (0 = off)", "0.01"),
    Rule(f"{_MODEL}.entropy_weight", at_least(0.0), "a weight >= 0 (0 = off)", "0.00003"),
    Rule(f"{_MODEL}.entropy_threshold", within(0.0, 1.0), "an accumulation in [0, 1]", "0.1"),
    Rule(f"{_MODEL}.entropy_unseen_rays", int_at_least(0), "an integer >= 0 (0 = the training rays only)", "1024"),
    Rule(f"{_MODEL}.depth_smoothness_patches", int_at_least(1), "an integer >= 1", "4"),
    Rule(f"{_MODEL}.depth_smoothness_patch_size", int_at_least(2), "a patch side >= 2 pixels", "8"),
    Rule(f"{_MODEL}.cull_weight_threshold", within(0.0, 1.0), "a weight in [0, 1] (0 = off)", "1e-4"),
    Rule(f"{_MODEL}.occlusion_fraction", within(1e-9, 1.0), "a fraction of the ray in (0, 1]", "0.15625"),
    Rule(f"{_MODEL}.floaters_gradient_scaling_from", within(0.0, 1.0), "a fraction of the run in [0, 1]", "0.2667"),
    Rule(
        f"{_MODEL}.random_background_from",
        optional(within(0.0, 1.0)),
        "a fraction of the run in [0, 1] (omitted = after the first occupancy update)",
        "0.2",
    ),
    Rule(f"{_ACCEL}.render_chunk_rays", int_at_least(1), "an integer >= 1", "2048"),
    Rule(f"{_ACCEL}.early_stop_transmittance", within(0.0, 0.5), "a transmittance in [0, 0.5]", "1e-4"),
    Rule(f"{_ACCEL}.early_stop_segment", int_at_least(1), "an integer >= 1", "128"),
    Rule(f"{_ACCEL}.checkpoint_above", int_at_least(0), "a sample count >= 0 (0 = never)", "65536"),
    Rule(f"{_ACCEL}.checkpoint_chunk", int_at_least(1), "an integer >= 1", "32768"),
    Rule(f"{_ACCEL}.dense_train_max_vertices", int_at_least(0), "a vertex count >= 0 (0 = never)", "4194304"),
    Rule(f"{_ACCEL}.dense_render_max_mb", at_least(0.0), "a size in MB >= 0 (0 = never)", "512"),
    Rule(f"{_MODEL}.field.n_voxels_init", int_at_least(8), "a voxel count >= 8 (2 per axis)", "2097152"),
    Rule(f"{_MODEL}.field.n_voxels_final", int_at_least(8), "a voxel count >= 8 (2 per axis)", "27000000"),
    Rule(f"{_MODEL}.field.density_components", each(int_at_least(1)), "component counts >= 1", "16 16 16"),
    Rule(f"{_MODEL}.field.appearance_components", each(int_at_least(1)), "component counts >= 1", "48 48 48"),
    Rule(f"{_MODEL}.field.appearance_dim", int_at_least(1), "an integer >= 1", "27"),
    Rule(f"{_MODEL}.field.hidden_dim", int_at_least(1), "an integer >= 1", "128"),
    Rule(f"{_MODEL}.field.feature_frequencies", int_at_least(0), "an integer >= 0 (0 = no encoding)", "2"),
    Rule(f"{_MODEL}.field.view_frequencies", int_at_least(0), "an integer >= 0 (0 = no encoding)", "2"),
    Rule(f"{_MODEL}.field.init_scale", optional(positive), "a standard deviation > 0 (or omitted)", "0.1"),
    Rule(f"{_MODEL}.field.revive_patience", int_at_least(1), "a count of training batches >= 1", "16"),
    Rule("optimizer.lr_grids", positive, "a learning rate > 0", "0.02"),
    Rule("optimizer.lr_networks", positive, "a learning rate > 0", "1e-3"),
    Rule("optimizer.lr_generator", positive, "a learning rate > 0", "2e-3"),
    Rule("optimizer.generator_grad_clip", at_least(0.0), "a gradient norm >= 0 (0 = never clip)", "0.32"),
    Rule("optimizer.betas", each(within(0.0, 1.0 - 1e-12)), "two numbers in [0, 1)", "0.9 0.98"),
    Rule("optimizer.betas_after_reset", optional(each(within(0.0, 1.0 - 1e-12))), "two numbers in [0, 1)", "0.9 0.98"),
    Rule("optimizer.weight_decay", at_least(0.0), "a number >= 0", "0.2"),
    Rule("optimizer.lr_decay_ratio", positive, "a ratio > 0 (1 = no decay)", "0.1"),
    Rule("optimizer.lr_warmup_fraction", within(0.0, 1.0), "a fraction of the run in [0, 1] (0 = none)", "0.0073"),
    Rule("optimizer.lr_warmup_start", within(1e-9, 1.0), "a multiplier in (0, 1]", "0.01"),
    Rule("optimizer.grad_clip_value", at_least(0.0), "a gradient value >= 0 (0 = never clip)", "0.1"),
    Rule("optimizer.grad_clip_norm", at_least(0.0), "a gradient norm >= 0 (0 = never clip)", "0.1"),
)
_MLP = f"{_MODEL}.mlp"
MLP_RULES: tuple[Rule, ...] = (
    Rule(f"{_MLP}.depth", int_at_least(1), "an integer >= 1", "8"),
    Rule(f"{_MLP}.width", int_at_least(1), "an integer >= 1", "256"),
    Rule(f"{_MLP}.view_width", int_at_least(1), "an integer >= 1", "128"),
    Rule(f"{_MLP}.position_bands", int_at_least(0), "an integer >= 0 (0 = the raw position only)", "10"),
    Rule(f"{_MLP}.direction_bands", int_at_least(0), "an integer >= 0 (0 = the raw direction only)", "4"),
    Rule(f"{_MLP}.ramp_fraction", within(0.0, 1.0), "a fraction of the run in [0, 1] (0 = all bands at once)", "0.9"),
    Rule(f"{_MLP}.density_bias", lambda v: _number(v), "a finite number", "-1"),
    Rule(f"{_MLP}.density_noise", at_least(0.0), "a standard deviation >= 0 (0 = none)", "1.0"),
    Rule(f"{_MLP}.rgb_padding", within(0.0, 0.5), "a padding in [0, 0.5]", "0.001"),
    Rule(f"{_MODEL}.samples_per_level", int_at_least(0), "an integer >= 0 (0 = march the occupancy grid)", "128"),
    Rule(f"{_MODEL}.coarse_loss_weight", at_least(0.0), "a weight >= 0", "0.1"),
    Rule(f"{_MODEL}.resample_padding", at_least(0.0), "a padding >= 0", "0.01"),
)
"""FreeNeRF's MLP options (only where the model has an MLP field)."""


def flag_of(path: str) -> str:
    return "--" + path.replace("_", "-")


def _lookup(config: Any, path: str) -> Any:
    value = config
    for part in path.split("."):
        value = getattr(value, part)
    return value


def _show(value: Any) -> str:
    return " ".join(map(str, value)) if isinstance(value, (tuple, list)) else str(value)


ZERORF_EXAMPLES = {
    "noise_channels": "8",
    "feature_channels": "16",
    "decoder_width": "64",
    "noise_resolution": "0",
    "plane_channels": "256 128 64 64 32",
    "line_channels": "128 128 128 64 32 32",
}
"""ZeroRF's own values, the example each message gives."""


def check_zerorf_options(config: Any) -> None:
    """A UserError for the first ZeroRF generator option it cannot be built with (only when the field uses it)."""
    zerorf = generator_config(config.pipeline.model)
    if zerorf is None:
        return
    for name, needs in invalid_options(zerorf):
        flag = flag_of(f"{_MODEL}.zerorf.{name}")
        fail(
            f"{flag} {_show(getattr(zerorf, name))} is out of range: it must be {needs}",
            f"pass e.g. {flag} {ZERORF_EXAMPLES[name]} (ZeroRF's value)",
        )


def check_mlp_options(config: Any) -> None:
    """A UserError for the first option an MLP field (freenerf) cannot be built or trained with: its own out of
    range, or one that only a factor grid reads (the grids' curriculum, TV, L1, the short-run defaults)."""
    model = config.pipeline.model
    mlp = mlp_config(model)
    if mlp is None:
        return
    for rule in MLP_RULES:
        value = _lookup(config, rule.path)
        if not rule.ok(value):
            flag = flag_of(rule.path)
            fail(f"{flag} {_show(value)} is out of range: it must be {rule.needs}", f"pass e.g. {flag} {rule.example}")
    if not 0 <= mlp.skip <= max(0, mlp.depth - 2):
        flag = flag_of(f"{_MLP}.skip")
        fail(
            f"{flag} {_show(mlp.skip)} is out of range: the input rejoins after a layer before the last, so it must be "
            f"0 (never) to {max(0, mlp.depth - 2)} with {flag_of(f'{_MLP}.depth')} {mlp.depth}",
            f"pass e.g. {flag} 4",
        )
    grid_only = [name for name in GRID_ONLY_OPTIONS if getattr(model, name) != 0]
    if grid_only:
        flag = flag_of(f"{_MODEL}.{grid_only[0]}")
        fail(
            f"{flag} {getattr(model, grid_only[0])} regularises factor grids; freenerf's field is an MLP",
            f"drop {flag}",
        )
    if model.fourier.enabled:
        flag = flag_of(f"{_MODEL}.fourier.enabled")
        fail(
            f"{flag} True low-passes factor grids; freenerf's field is an MLP, whose curriculum is its encoding's mask",
            f"drop {flag}; {flag_of(f'{_MLP}.ramp_fraction')} sets how fast the mask opens",
        )
    if config.budget_rule:
        fail(
            "--budget-rule True applies the short-run defaults of factor grids; freenerf's field is an MLP and keeps "
            "FreeNeRF's values at any budget",
            "drop --budget-rule",
        )


MLP_SAMPLING_OPTIONS = ("n_voxels_init", "n_voxels_final", "upsample_fractions")
"""The ``field`` options an MLP field reads: the size and schedule of the grid the sampler and occupancy grid use."""
MLP_IGNORED = ("optimizer.lr_grids", "optimizer.lr_generator", "optimizer.generator_grad_clip")
"""Optimiser options of parameter groups an MLP field does not have (its one group is ``networks``)."""
LEVELS_IGNORED = (f"{_MODEL}.step_ratio", f"{_MODEL}.occupancy_update_fractions")
"""Sampling options that FreeNeRF's two levels (``samples_per_level``) do not read, beside the grid's ``field`` ones."""


def check_mlp_flags(config: Any, given: frozenset[str]) -> None:
    """One UserError naming every typed flag (``given``: config paths) that nothing reads in an MLP field's run: the
    factor grids' components, decoder and activation, the grids' curriculum, the grids' learning rates."""
    if mlp_config(config.pipeline.model) is None:
        return
    field, fourier = f"{_MODEL}.field.", f"{_MODEL}.fourier."
    unread = sorted(
        path
        for path in given
        if (path.startswith(field) and path[len(field) :] not in MLP_SAMPLING_OPTIONS)
        or path.startswith(fourier)
        or path in MLP_IGNORED
    )
    levels = config.pipeline.model.samples_per_level
    sampling = [p for p in given if p in LEVELS_IGNORED or p.startswith(field)] if levels and not unread else []
    if sampling:
        flags = " ".join(flag_of(path) for path in sorted(sampling))
        fail(
            f"{flags}: set the grid freenerf steps through and its occupancy grid, which FreeNeRF's two levels "
            f"({flag_of(f'{_MODEL}.samples_per_level')} {levels}) do not use",
            f"drop {flags}, or pass {flag_of(f'{_MODEL}.samples_per_level')} 0 to march the occupancy grid",
        )
    if unread:
        flags = " ".join(flag_of(path) for path in unread)
        fail(
            f"{flags}: read by factor grids only; freenerf's field is an MLP ({flag_of(_MLP)}.*), which ignores them",
            f"drop {flags}; the MLP's own options are under {flag_of(_MLP)} and its lr is --optimizer.lr-networks",
        )


def check_final_cutoff(fourier: Any) -> None:
    """The band only opens: an initial cutoff above the final one is a contradiction, not a schedule."""
    own_color_final = fourier.f_final_color is not None
    pairs = (("f0_density", "f_final"), ("f0_color", "f_final_color" if own_color_final else "f_final"))
    for name, final_name in pairs:
        f0, final = getattr(fourier, name), getattr(fourier, final_name)
        if fourier.enabled and f0 > final:
            final_flag = flag_of(f"{_MODEL}.fourier.{final_name}")
            fail(
                f"{flag_of(f'{_MODEL}.fourier.{name}')} {f0} is above {final_flag} {final}: the cutoff only grows",
                f"pass {final_flag} {f0} or more, or a smaller initial cutoff",
            )


def _some_axes(axes: Any) -> bool:
    """Whether ``density_axes`` leaves out an axis (the paper filters all three)."""
    return sorted(axes) != list(ALL_AXES)


BAND_OPTIONS: tuple[tuple[str, Callable[[Any], bool], str], ...] = (
    ("boundary", lambda v: v == "mirror", "nothing is filtered"),
    ("density_axes", _some_axes, "nothing is filtered"),
)
"""Options of the band itself: (field, whether its value needs a band, why it would mean nothing without one)."""


def check_band_options(fourier: Any) -> None:
    """An option of the band means nothing without a band: refuse it rather than ignore it."""
    for name, needs_band, why in BAND_OPTIONS:
        value = getattr(fourier, name)
        if needs_band(value) and not fourier.enabled:
            flag = flag_of(f"{_MODEL}.fourier.{name}")
            fail(
                f"{flag} {_show(value)} needs the Fourier curriculum, which is off in this run (a tensorf-* preset or "
                f"{flag_of(f'{_MODEL}.fourier.enabled')} False): {why}",
                f"drop {flag}, or train a fourierf-* preset",
            )


BAND_VALUES = ("f0_density", "f0_color", "ramp_fraction", "f_final", "f_final_color", "plane_leakage")
"""Values of the curriculum's schedule: without the band nothing reads them."""


def ignored_band_flags(config: Any, given: frozenset[str]) -> list[str]:
    """The schedule flags typed (``given``: config paths) for a run whose Fourier curriculum is off, where they are
    read by nothing (a tensorf-* preset, or ``--pipeline.model.fourier.enabled False``)."""
    if config.pipeline.model.fourier.enabled:
        return []
    return [flag_of(f"{_MODEL}.fourier.{name}") for name in BAND_VALUES if f"{_MODEL}.fourier.{name}" in given]


def check_density_axes(model: Any) -> None:
    """Filtering the density along some axes only is an option of free factor grids: refuse it for ZeroRF's field,
    whose generated factors are filtered along every axis, rather than ignore it."""
    axes = model.fourier.density_axes
    if _some_axes(axes) and generator_config(model) is not None:
        flag = flag_of(f"{_MODEL}.fourier.density_axes")
        fail(
            f"{flag} {_show(axes)} applies to free factor grids; ZeroRF's generated factors are filtered along "
            "every axis",
            f"drop {flag}, or train fourierf-vm or fourierf-cp",
        )


def check_floaters_start(model: Any) -> None:
    """A start for a gradient scaling that is off would be ignored: refuse it, as a band option without a band."""
    start = model.floaters_gradient_scaling_from
    if start > 0 and not model.floaters_gradient_scaling:
        flag = flag_of(f"{_MODEL}.floaters_gradient_scaling_from")
        on = flag_of(f"{_MODEL}.floaters_gradient_scaling")
        fail(
            f"{flag} {start} starts Floaters-No-More gradient scaling, which is off in this run: nothing to start",
            f"add {on} True, or drop {flag}",
        )


EVENT_SCHEDULES = (f"{_MODEL}.field.upsample_fractions", f"{_MODEL}.occupancy_update_fractions")
"""Events placed at fractions of the run: each must land on a step inside it."""


TRAINING_COPIES = 6
"""Float32 copies of every grid value in training: the parameter, its gradient, AdamW's two moments, the filtered
copy and its gradient."""


def check_ranges(config: Any) -> None:
    """A UserError for the first option outside its range (``RULES``, the iteration count, ZeroRF's generator)."""
    for rule in RULES:
        value = _lookup(config, rule.path)
        if not rule.ok(value):
            flag = flag_of(rule.path)
            fail(f"{flag} {_show(value)} is out of range: it must be {rule.needs}", f"pass e.g. {flag} {rule.example}")
    check_zerorf_options(config)
    check_mlp_options(config)
    iters = config.max_num_iterations
    if not (_integer(iters) and iters >= 1):
        fail(f"--max-num-iterations must be at least 1, got {iters}", "pass a positive number")


def check_saved_config(config: Any, path: Any) -> None:
    """The range checks on a config read back from a run's ``config.json`` (eval, render, export), and its largest
    grid against the memory available now: a hand-edited or damaged value fails here, naming the file, before
    anything is allocated."""
    try:
        check_ranges(config)
    except UserError as err:
        raise UserError(
            f"{path} holds a value out of range: {err.problem}",
            f"restore the value the run was trained with in {path} ({err.fix}), or retrain",
        ) from err
    field = config.pipeline.model.field
    voxels = max(field.n_voxels_init, field.n_voxels_final)
    check_fits(
        grid_values(field, voxels) * 4,
        f"the grid of {path} ({voxels} voxels)",
        "load the run on a machine with more memory, or restore the voxel counts it was trained with",
    )


def check_training_options(config: Any, copies: int = TRAINING_COPIES) -> None:
    """Raise a UserError for the first option outside its valid range (a ``TrainerConfig`` is expected); the grid
    must fit with ``copies`` float32 copies of each value (training's, or 1 to render a saved run)."""
    check_ranges(config)
    check_final_cutoff(config.pipeline.model.fourier)
    check_band_options(config.pipeline.model.fourier)
    check_floaters_start(config.pipeline.model)
    check_density_axes(config.pipeline.model)
    iters = config.max_num_iterations
    for path in EVENT_SCHEDULES:
        fractions = _lookup(config, path)
        try:
            steps_from_fractions(fractions, iters)
        except ValueError as err:
            flag = flag_of(path)
            inside = [f for f in fractions if 0 < f < 1]
            needed = f" (at least {max(2, math.ceil(1 / min(inside)))} here)" if inside else ""
            fail(
                f"{flag} {_show(fractions)} does not fit a run of {iters} iterations ({err})",
                "use fractions strictly between 0 and 1 and a --max-num-iterations long enough to place them"
                f"{needed}, or pass {flag} with no value to disable them",
            )
    check_grid_fits(config, copies=copies)


def grid_values(field: Any, n_voxels: float) -> float:
    """Grid values of a field config at ``n_voxels`` (a cubic box: planes of side², lines of side)."""
    side = n_voxels ** (1.0 / 3.0)
    components = sum(field.density_components) + sum(field.appearance_components)
    if field.decomposition == "cp":
        return (field.density_components[0] + field.appearance_components[0]) * 3 * side
    return components * (side * side + side)


def check_grid_fits(config: Any, available: int | None = None, copies: int = TRAINING_COPIES) -> None:
    """A UserError, before anything is built, when the largest grid of the run (the initial one or the final one,
    whichever is larger) cannot fit in the memory available now; ``copies``: float32 copies held of each value."""
    field = config.pipeline.model.field
    name = "n_voxels_init" if field.n_voxels_init > field.n_voxels_final else "n_voxels_final"
    voxels = getattr(field, name)
    needed = grid_values(field, voxels) * 4 * copies
    free = available_memory() if available is None else available
    if free is None or needed <= free:
        return
    side = (free / 2 / (4 * copies * grid_values(field, 1.0) / 2)) ** 0.5  # room for the rest of the run
    flag = flag_of(f"{_MODEL}.field.{name}")
    check_fits(
        needed,
        f"the {'initial' if name == 'n_voxels_init' else 'final'} grid ({flag} {voxels})",
        f"pass at most {flag} {int(side) ** 3} on this machine (300^3 = 27000000 is the paper's final grid)",
        free,
    )
