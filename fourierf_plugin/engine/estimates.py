"""What a run will cost, printed before it starts: training time on a CPU and the size of its checkpoints."""

from __future__ import annotations

import math
from typing import Any

from fourierf_plugin.data.datamanager import rays_per_batch_at
from fourierf_plugin.engine.option_checks import grid_values
from fourierf_plugin.field_components.generator import parameter_count
from fourierf_plugin.field_components.schedules import steps_from_fractions, voxel_counts
from fourierf_plugin.fields.mlp_field import parameter_count as mlp_parameter_count
from fourierf_plugin.models.freenerf import LEVELS, mlp_config
from fourierf_plugin.models.zerorf import generator_config
from fourierf_plugin.utils.console import format_duration

SECONDS_PER_RAY_STEP = 1.05e-6
"""A CPU iteration's cost per ray and per voxel of the final grid's side on 2 threads, fitted to the default CPU run
(``benchmarks/ab_speed.py`` times it): an estimate, not a promise."""


SECONDS_PER_ZERORF_RAY_STEP = 4.3e-6
"""A zerorf-vm iteration's cost per ray and per voxel of the final grid's side, 2 threads: ZeroRF's decoder reads six
factors and a 64-wide layer at every sample it keeps, and its culling evaluates the density twice; fitted between an
object (whose box the occupancy grid crops) and a forward-facing scene (whose frustum it fills)."""


SECONDS_PER_GENERATED_VALUE = 1.0e-6
"""A zerorf-vm iteration's added cost per value its generators draw (forward and backward, ZeroRF's widths, 2 threads),
fitted to ZeroRF's three canvases at the default CPU grid."""


def mean_rays_per_batch(config: Any) -> float:
    """Training rays per iteration averaged over the run (a batch schedule, such as ZeroRF's, grows it)."""
    manager, iterations = config.pipeline.datamanager, max(1, config.max_num_iterations)
    schedule = getattr(manager, "rays_per_batch_schedule", None)
    if not schedule:
        return float(manager.rays_per_batch)
    return (
        sum(rays_per_batch_at(s, manager.rays_per_batch, schedule, iterations) for s in range(iterations)) / iterations
    )


SECONDS_PER_MLP_WEIGHT = 1.2e-10
"""An MLP field's (freenerf's) training cost per sample and per network weight (a forward and backward pass), 2 threads,
measured on the bundled scene before the first occupancy update: an estimate, not a promise."""


def mlp_seconds_per_iteration(config: Any, rays: float) -> float:
    """An MLP field's iteration: every sample through the whole network, its two levels' samples (FreeNeRF's sampler)
    or every step through the box (the sampler's step through the run's mean grid, before the occupancy grid skips
    empty space: an upper bound)."""
    model = config.pipeline.model
    side = model.field.n_voxels_init ** (1.0 / 3.0) * grid_growth(config)
    samples = LEVELS * model.samples_per_level or math.sqrt(3.0) * side / model.step_ratio
    return rays * samples * mlp_parameter_count(model.mlp) * SECONDS_PER_MLP_WEIGHT


def estimate_seconds(config: Any, threads: int) -> float:
    """A CPU run's training time from the measured cost (scaled by the threads it gets)."""
    field = config.pipeline.model.field
    side = field.n_voxels_final ** (1.0 / 3.0)
    rays = mean_rays_per_batch(config) + config.pipeline.model.unseen_rays()
    zerorf = generator_config(config.pipeline.model)
    per_iteration = rays * side * (SECONDS_PER_RAY_STEP if zerorf is None else SECONDS_PER_ZERORF_RAY_STEP)
    if mlp_config(config.pipeline.model) is not None:
        per_iteration = mlp_seconds_per_iteration(config, rays)
    if zerorf is not None:  # a cubic box's canvases: the smallest multiple of 2^levels covering the final grid
        scale = 2**zerorf.upsample_levels
        noise = zerorf.noise_resolution or math.ceil(side / scale)
        canvas = scale * noise
        per_iteration += 3 * canvas**2 * zerorf.feature_channels * SECONDS_PER_GENERATED_VALUE
    return config.max_num_iterations * per_iteration * 2.0 / max(1, threads)


RUN_TO_GROWTH = 0.9
"""A run's average cost per iteration over its first iterations' cost times the grid's growth (``grid_growth``): what
the growth leaves out (the field lights up, the occupancy updates shrink the box and filter the rays), fitted on an
object and a forward-facing scene at the CPU sizing; an estimate, which ``time_budget.MARGIN`` covers."""

REST_TO_GROWTH = {
    "grid": {"euclidean": 0.62, "ndc": 1.3, "contracted": 1.0},
    "decoder": {"euclidean": 0.36, "ndc": 1.0, "contracted": 1.0},
}
"""A run's cost per iteration after its first events over its cost before them times the grid's growth, by what an
iteration's cost follows and the scene's ray space. An object's box (euclidean rays) is mostly empty: once the
occupancy grid skips that space an iteration costs far less than the growth says, and less still where a decoder at
every sample (ZeroRF's, an MLP field's) is most of the cost, rather than a grid model's filtering of its whole
grids. A forward-facing scene (NDC) fills its frustum, and a grid's planes cost more than their side as they grow.
Fitted on the bundled lego and on fern at the CPU sizing (the rows or spaces not fitted, an unbounded scene's and a
decoder's on NDC, take the growth as it is); an estimate, which ``time_budget.MARGIN`` and the last re-plan cover."""


def cost_kind(model: Any) -> str:
    """What an iteration's cost of a model config follows (a key of ``REST_TO_GROWTH``): a decoder at every sample
    (generated factors, an MLP field) or the grids."""
    return "decoder" if generator_config(model) is not None or mlp_config(model) is not None else "grid"


SAVE_BYTES_PER_SECOND = 200e6
"""How fast a checkpoint is written (serialised and flushed to disk): an estimate for a local disk."""


def grid_growth(config: Any, upto: int | None = None, iterations: int | None = None) -> float:
    """The run's mean grid side over its initial one, iteration by iteration along the upsample schedule, over its
    first ``upto`` iterations (all by default), the run ``iterations`` long (default: its own count): a ray's
    samples, and so an iteration's cost, grow with the side."""
    field = config.pipeline.model.field
    iterations = config.max_num_iterations if iterations is None else iterations
    end = iterations if upto is None else max(1, min(upto, iterations))
    steps = steps_from_fractions(field.upsample_fractions, iterations)
    counts = [field.n_voxels_init, *voxel_counts(field.n_voxels_init, field.n_voxels_final, len(steps))]
    edges = [0, *steps, iterations]
    spans = zip(edges, edges[1:], counts, strict=False)  # one count per span; edges has one more entry
    total = sum(
        (min(stop, end) - start) * (n / field.n_voxels_init) ** (1 / 3) for start, stop, n in spans if start < end
    )
    return total / end


def fitting_iterations(config: Any, done: int, seconds: float, available_s: float) -> int:
    """The count whose whole run fits ``available_s``, at the cost ``config``'s run measured over its first ``done``
    iterations (``seconds``): that cost per unit of grid side, times the whole run's mean side (a run cut short saw
    fewer of its upsamples than a whole run does)."""
    per_side = seconds / (done * grid_growth(config, done))
    return max(1, math.floor(available_s / (per_side * grid_growth(config))))


def rest_seconds(config: Any, iterations: int, done: int, seconds_per_iteration: float) -> float:
    """What iterations ``done`` to ``iterations`` of a run of ``iterations`` cost, at ``seconds_per_iteration`` timed
    on its initial grid before any of its events (a ``--time-budget`` run's re-plan): that cost per unit of grid side,
    times each iteration's side, times ``REST_TO_GROWTH`` of its cost's kind and its scene."""
    sides = iterations * grid_growth(config, iterations=iterations) - done * grid_growth(config, done, iterations)
    ratio = REST_TO_GROWTH[cost_kind(config.pipeline.model)][config.pipeline.effects.ray_space]
    return seconds_per_iteration * sides * ratio


def run_shape(config: Any) -> float:
    """A run's average cost per iteration over the cost of its first iterations (what ``--time-budget`` times)."""
    return grid_growth(config) * RUN_TO_GROWTH


def save_seconds(size_bytes: float) -> float:
    """The time one checkpoint of ``size_bytes`` takes to write."""
    return size_bytes / SAVE_BYTES_PER_SECOND


def checkpoint_bytes(config: Any, rays: int) -> float:
    """One checkpoint: the final grid's values with AdamW's two moments, the training rays' state, the rest."""
    field = config.pipeline.model.field
    zerorf = generator_config(config.pipeline.model)
    mlp = mlp_config(config.pipeline.model)
    if mlp is not None:
        values = float(mlp_parameter_count(mlp))
    elif zerorf is not None:
        values = parameter_count(zerorf)
    else:
        values = grid_values(field, field.n_voxels_final)
    return values * 4 * 3 + rays * 16 + 1e6


def describe_cost(config: Any, rays: int, threads: int, cpu: bool) -> str:
    """The line printed before training: how long (on a CPU, or as a time budget planned it) and how large the run
    will be."""
    size = checkpoint_bytes(config, rays) / 2**20
    text = f"checkpoints of ~{size:.0f} MB each, the last {config.keep_checkpoints} kept"
    planned = getattr(config, "planned_train_seconds", None)
    if planned is not None:
        text += f"; planned training time ~{format_duration(planned)} (--time-budget {config.time_budget})"
    elif cpu:
        text += f"; estimated training time ~{format_duration(estimate_seconds(config, threads))} on {threads} threads"
    return text
