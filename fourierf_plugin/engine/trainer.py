"""Training loop: seeding, device, run directory, schedules, checkpoints (atomic, resumable), Ctrl-C safety."""

from __future__ import annotations

import bisect
import contextlib
import copy
import functools
import itertools
import json
import math
import os
import signal
import statistics
import time
from collections import Counter
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import ClassVar, Literal, NamedTuple

import torch
import tyro
from rich.markup import escape

from fourierf_plugin import __version__
from fourierf_plugin.accel.config import uses_gpu_paths
from fourierf_plugin.configs.base import InstantiateConfig, save_config
from fourierf_plugin.data.datamanager import DataManager
from fourierf_plugin.data.dataparser_transforms import write_run_frame
from fourierf_plugin.engine.checkpoint import list_checkpoints, load_latest_checkpoint, save_checkpoint
from fourierf_plugin.engine.estimates import describe_cost, fitting_iterations, rest_seconds
from fourierf_plugin.engine.health import DEAD_FIELD_FIX, dead_field_problem, flat_colour_psnr
from fourierf_plugin.engine.machine import pick_device, seed_everything
from fourierf_plugin.engine.observers import (
    StepReport,
    TrainingObserver,
    notify_finished,
    notify_started,
    notify_step,
)
from fourierf_plugin.engine.optimizers import OptimizerConfig, build_optimizer, set_learning_rates
from fourierf_plugin.engine.option_checks import check_training_options
from fourierf_plugin.engine.run_dir import lock_run, make_run_dir, views_record
from fourierf_plugin.exporter.marching_cubes import describe, export_field_mesh
from fourierf_plugin.models.fourierf import FourieRFModel
from fourierf_plugin.pipelines.base import Pipeline, PipelineConfig
from fourierf_plugin.utils.console import (
    TaskProgress,
    append_jsonl,
    cpu_threads_note,
    format_duration,
    get_console,
    warn,
)
from fourierf_plugin.utils.errors import UserError, fail
from fourierf_plugin.utils.phases import PhaseTimer, phase


def drop_records_after(path: Path, step: int) -> None:
    """Forget log lines past the checkpoint a run resumes from (a killed run logged steps it never saved).

    Rewritten atomically, so a crash here cannot lose the log either. A last line cut short (what a power cut or a
    full disk leaves) is dropped with a warning; a damaged line elsewhere is a clear error.
    """
    if not path.is_file():
        return
    lines = path.read_text(errors="replace").splitlines(keepends=True)
    records = []
    for number, line in enumerate(lines, 1):
        if not line.strip():
            continue
        try:
            records.append((line if line.endswith("\n") else line + "\n", json.loads(line)))
        except json.JSONDecodeError:
            if number < len(lines):
                fail(f"{path}, line {number}, is not JSON", "delete that line (or the file), then resume")
            warn(f"{path}: its last line is cut short (the run stopped while writing it): dropped")
    kept = [line for line, r in records if r.get("step", 0) <= step and r.get("event") != "done"]
    if kept == lines:
        return
    tmp = path.with_name(path.name + ".tmp")
    tmp.write_text("".join(kept))
    os.replace(tmp, path)


def divergence_fix(optimizer: OptimizerConfig) -> str:
    """What most likely made a run diverge: a learning rate above its default, else the scene's cameras."""
    defaults = OptimizerConfig()
    raised = [
        f"--optimizer.{name.replace('_', '-')} {getattr(optimizer, name):g} (default {getattr(defaults, name):g})"
        for name in ("lr_grids", "lr_networks", "lr_generator")
        if getattr(optimizer, name) > getattr(defaults, name)
    ]
    if raised:
        return f"lower {', '.join(raised)} and train again"
    return (
        "check the scene's cameras (a zero or negative focal length, poses far from the others), or lower "
        "--optimizer.lr-grids, and train again"
    )


STOP_SIGNALS = tuple(getattr(signal, name) for name in ("SIGINT", "SIGTERM", "SIGHUP") if hasattr(signal, name))
"""Ctrl-C, and what a job scheduler, ``timeout``, a closed SSH session or a container stop sends."""


REPEAT_SECONDS = 1.0
"""A second stop signal this soon after the first is the same request (a double tap), not an abort."""


class _DeferredStop:
    """The first stop signal asks the loop to stop at the end of the current step (and save); a second one, a second
    or more later, aborts."""

    def __init__(self) -> None:
        self.signal: int | None = None
        self._first = 0.0
        self._previous: dict[int, object] = {}

    @property
    def requested(self) -> bool:
        return self.signal is not None

    @property
    def exit_code(self) -> int:
        """The shell's convention for a process ended by the signal: 128 + its number (Ctrl-C: 130)."""
        return 128 + int(self.signal or signal.SIGINT)

    def __enter__(self) -> _DeferredStop:
        try:
            for signum in STOP_SIGNALS:
                self._previous[signum] = signal.signal(signum, self._handle)
        except ValueError:  # not the main thread: leave signals alone
            self.__exit__()
        return self

    def _handle(self, signum, frame) -> None:
        if self.requested:
            if time.monotonic() - self._first < REPEAT_SECONDS:
                return  # one key press that sent two signals, or a double tap: still the first request
            raise KeyboardInterrupt
        self.signal = signum
        self._first = time.monotonic()

    def __exit__(self, *exc) -> None:
        for signum, previous in self._previous.items():
            signal.signal(signum, previous)  # type: ignore[arg-type]
        self._previous = {}


def optimisation_step(
    pipeline: Pipeline,
    optimizer: torch.optim.Optimizer,
    config: OptimizerConfig,
    step: int,
    reset_steps: list[int],
    max_iters: int,
) -> tuple[torch.optim.Optimizer, dict[str, torch.Tensor], float]:
    """One iteration as a run makes it: the learning rates of ``step``, loss, backward, the optimiser's step and the
    structure changes after it. Returns the optimiser for the next step (rebuilt where parameters were replaced), the
    step's metrics (still on the device) and the learning-rate scale."""
    lr_scale = set_learning_rates(optimizer, config, step, reset_steps, max_iters)
    loss, metrics = pipeline.train_step(step)
    with phase("backward"):
        optimizer.zero_grad(set_to_none=True)
        loss.backward()
    with phase("optimizer"):
        optimizer.step()
    if pipeline.after_step(step).params_replaced:
        optimizer = build_optimizer(config, pipeline.model.param_groups(), step + 1, reset_steps)
    return optimizer, metrics, lr_scale


class Trainer:
    config: TrainerConfig

    def __init__(self, config: TrainerConfig, observers: Sequence[TrainingObserver] = ()) -> None:
        """``observers`` watch the run (the viewer, TensorBoard: ``scripts.observers.build_observers`` makes the ones
        ``config.viewer``/``config.vis`` ask for); the trainer only tells them what happened."""
        self.config = config
        self.observers = list(observers)
        self.console = get_console()
        self.start_step = 0
        self.resume_state: dict | None = None
        self.last_finite_loss: tuple[int, float] | None = None
        """The step and value of the latest finite training loss read (named when the loss diverges)."""
        check_training_options(config)  # the Python API gets the same option checks as the CLI
        if not config.pipeline.effects.is_resolved:
            raise ValueError(
                "the trainer takes a finished config: pass it through fourierf_plugin.method_configs.finalize "
                "(fourierf-train does), which resolves the scene's effects and preset"
            )
        c = config
        outside = [s for s in c.export_mesh_at if not 1 <= s <= c.max_num_iterations]
        if outside:
            fail(
                f"--export-mesh-at {outside} lies outside the run's 1..{c.max_num_iterations} iterations",
                "pass iteration numbers within the run",
            )
        if c.load_dir is not None:
            _, self.resume_state = load_latest_checkpoint(Path(c.load_dir) / "checkpoints")
            self.start_step = int(self.resume_state["step"])
        if c.threads is not None:
            torch.set_num_threads(c.threads)
        self.device = pick_device(c.device)
        self.generator = seed_everything(c.seed)
        self.pipeline: Pipeline = c.pipeline.setup(
            device=self.device, max_iters=c.max_num_iterations, generator=self.generator
        )
        if self.resume_state is None:
            scene = self.pipeline.datamanager.reference_outputs
            self.run_dir = make_run_dir(c.output_dir, scene.scene_name, c.method_name, c.timestamp)
            data, run = Path(c.pipeline.datamanager.dataparser.data).resolve(), self.run_dir.resolve()
            if os.path.commonpath([data, run]) != data.anchor:  # beside each other, not only on the same disk
                c.data_from_run_dir = Path(os.path.relpath(data, run))
        else:
            assert c.load_dir is not None
            self.run_dir = Path(c.load_dir)
        self.run_lock = lock_run(self.run_dir)  # before anything is written: one trainer per run folder
        self.checkpoint_dir = self.run_dir / "checkpoints"
        self.checkpoint_dir.mkdir(exist_ok=True)
        save_config(c, self.run_dir / "config.json")
        self._write_views()
        write_run_frame(self.run_dir, self.pipeline.datamanager.reference_outputs, self.pipeline.effects.ray_space)
        self._announce()

    # -- set-up ---------------------------------------------------------------------------------------------------
    def _write_views(self) -> None:
        record = views_record(self.pipeline.datamanager.reference_outputs)
        (self.run_dir / "views.json").write_text(json.dumps(record, indent=2) + "\n")

    def _announce(self) -> None:
        scene = self.pipeline.datamanager.reference_outputs
        model = self.pipeline.model
        self.console.print(
            f"[bold]{escape(self.config.method_name)}[/bold] on {escape(scene.scene_name)}: "
            f"run directory {escape(str(self.run_dir))}"
        )
        self.console.print(f"training views ({len(scene.view_ids)}): {escape(', '.join(scene.image_names))}")
        self.console.print(f"scene effects: {model.effects.describe()}; {self.config.scene_preset} preset")
        self.console.print(
            f"device {self.device} ({cpu_threads_note(torch.get_num_threads())}), grid {model.field.resolution}, "
            f"{self.config.max_num_iterations} iterations, "
            f"occupancy updates after {model.occupancy_steps}, upsamples after {model.upsample_steps}"
        )
        rays = int(self.pipeline.datamanager.active.numel())
        self.console.print(describe_cost(self.config, rays, torch.get_num_threads(), self.device.type == "cpu"))
        if self.start_step:
            self.console.print(f"resuming at step {self.start_step}")

    # -- checkpoints ----------------------------------------------------------------------------------------------
    def _state(self, step: int, optimizer: torch.optim.Optimizer) -> dict:
        return {
            "step": step,
            "fourierf_version": __version__,
            "pipeline": self.pipeline.state_dict(),
            "optimizer": optimizer.state_dict(),
            "generator": self.generator.get_state(),
            "torch_rng": torch.get_rng_state(),
        }

    def save(self, step: int, optimizer: torch.optim.Optimizer) -> Path:
        """Checkpoint ``step``; parameters that are no longer finite end the run instead, so a diverged state never
        displaces the last good checkpoint."""
        if not all(bool(torch.isfinite(p).all()) for p in self.pipeline.model.parameters()):
            self._diverged(step, float("nan"))
        return save_checkpoint(self._state(step, optimizer), self.checkpoint_dir, step, self.config.keep_checkpoints)

    def _restore(self, state: dict, reset_steps: list[int]) -> torch.optim.Optimizer:
        self.pipeline.load_state_dict(state["pipeline"])
        groups = self.pipeline.model.param_groups()
        optimizer = build_optimizer(self.config.optimizer, groups, self.start_step, reset_steps)
        optimizer.load_state_dict(state["optimizer"])
        self.generator.set_state(state["generator"])
        torch.set_rng_state(state["torch_rng"])
        return optimizer

    def _export_mesh(self, step: int) -> None:
        """The coarse-to-fine trajectory as meshes; a mesh that cannot be made is a warning, never a lost run."""
        path = self.run_dir / "meshes" / f"step-{step:06d}.ply"
        try:
            report = export_field_mesh(self.pipeline.model, step, path, resolution=self.config.export_mesh_resolution)
        except UserError as err:
            warn(f"no mesh at step {step}: {err.problem}")
            return
        self.console.print(f"mesh at step {step}: " + "; ".join(describe(report)))

    # -- divergence -------------------------------------------------------------------------------------------------
    def _check_finite(self, step: int, shown: dict[str, float]) -> None:
        loss = shown.get("loss")
        if loss is None:
            return
        if not math.isfinite(loss):
            self._diverged(step, loss)
        self.last_finite_loss = (step, loss)

    def _diverged(self, step: int, loss: float) -> None:
        """End a run whose loss or parameters stopped being finite: one clear message naming the step, the last
        finite loss, the checkpoint kept and the likeliest cause."""
        append_jsonl(self.run_dir / "metrics.jsonl", {"event": "diverged", "step": step, "loss": str(loss)})
        last = self.last_finite_loss
        seen = f"last finite loss {last[1]:.4g} at step {last[0]}" if last else "no finite loss read before"
        kept = list_checkpoints(self.checkpoint_dir)
        keeps = f"its last finite checkpoint {kept[-1].name} is kept" if kept else "no checkpoint was saved"
        value = "NaN" if math.isnan(loss) else loss
        problem = f"the training loss became {value} at step {step} ({seen}); the run stopped, {keeps} ({self.run_dir})"
        fail(problem, divergence_fix(self.config.optimizer))

    # -- loop -------------------------------------------------------------------------------------------------------
    def _check_alive(self, done: int, shown: dict[str, float]) -> None:
        """A run whose field stayed empty, or renders worse than one flat colour, ends with a clear error."""
        images = self.pipeline.datamanager.reference_outputs.images
        problem = dead_field_problem(
            done, self.pipeline.model.empty_at_last_update, shown.get("psnr"), flat_colour_psnr(images)
        )
        if problem is not None:
            append_jsonl(self.run_dir / "metrics.jsonl", {"event": "dead_field", "step": done, "problem": problem})
            fail(f"{problem} after {done} iterations (run in {self.run_dir})", DEAD_FIELD_FIX)

    def train(self) -> Path:
        """Train to the end (or a stop signal, or a diverged loss); the run folder's lock is released either way."""
        try:
            return self._train()
        finally:
            self.run_lock.release()

    def _past_deadline(self, elapsed: float) -> bool:
        """Whether a --time-budget run has used its training time (a resumed run has no deadline: its time before the
        stop is not known here)."""
        deadline = self.config.train_deadline_seconds
        return deadline is not None and not self.start_step and elapsed >= deadline

    # -- the run's length, planned again from its own speed --------------------------------------------------------
    def _replan_window(self) -> ReplanWindow | None:
        """Where a fresh ``--time-budget`` run first times its own iterations and plans its length again: after its
        warm-up (``START_STEPS`` past any event among its first steps, such as a ray batch's first stages),
        ``REPLAN_SHARE`` of the way to its next count-dependent event, so that a shorter run still has that event ahead
        of it; None for too few steps (the last window may still come)."""
        events = self._planned_events()
        if events is None:
            return None
        events = [s for s in events if s > 0]  # one at 0 is the start's
        start = START_STEPS + max((s + 1 for s in events if s < START_STEPS), default=0)
        to = math.floor(REPLAN_SHARE * min((s for s in events if s >= start), default=self.config.max_num_iterations))
        return ReplanWindow(start, to, last=False) if to - start >= MIN_TIMED_STEPS else None

    def _last_window(self) -> ReplanWindow | None:
        """Where a fresh ``--time-budget`` run times its iterations once every count-dependent event is behind it (its
        grid final, its rays filtered: the cost the rest of the run has) and plans its length a last time; None where
        too few iterations follow its last event."""
        events, iterations = self._planned_events(), self.config.max_num_iterations
        if events is None:
            return None
        start = max(events, default=0) + 1 + START_STEPS
        to = start + max(MIN_TIMED_STEPS, math.ceil(LAST_TIMED_SHARE * iterations))
        return ReplanWindow(start, to, last=True) if to < iterations else None

    def _planned_events(self) -> list[int] | None:
        """The event steps of a fresh ``--time-budget`` run at its current length; None without a length plan or on
        resume (a resumed run keeps its length)."""
        c = self.config
        if c.length_plan is None or self.start_step:
            return None
        return self._event_steps(c.max_num_iterations) or []

    def _event_steps(self, iterations: int) -> list[int] | None:
        """The run's count-dependent event steps were it ``iterations`` long, from probes of its model and datamanager
        (the run itself unchanged); None where its schedules do not fit that many."""
        config = copy.deepcopy(self.config)
        model, manager = copy.copy(self.pipeline.model), copy.copy(self.pipeline.datamanager)
        model.config, manager.config = config.pipeline.model, config.pipeline.datamanager
        try:
            set_run_length(config, model, manager, iterations)
        except ValueError:
            return None
        return sorted(model.event_steps() + manager.stage_steps())

    def _events_behind(self, iterations: int, done: int) -> int | None:
        """How many of a run of ``iterations``'s events come before ``done`` (None where its schedules do not fit).
        Counts equal, the same events are behind: each is a fraction of the run or a fixed step."""
        then = self._event_steps(iterations)
        return None if then is None else sum(s < done for s in then)

    def _clock(self, started: float) -> float:
        """Seconds since ``started``, the device's queued work included."""
        if self.device.type == "cuda":
            torch.cuda.synchronize(self.device)
        return time.perf_counter() - started

    def _replan(self, done: int, stamps: Sequence[float], last: bool) -> bool:
        """Set the run's length to the count whose training fits its plan's time, ``stamps`` the clock after each
        iteration of its window: at their median seconds per iteration (which a hiccup of the machine moves little),
        the rest costing that per unit of grid side as the grid grows (``estimates.rest_seconds``) or, in the ``last``
        window (every event behind), that per iteration; within the short-run rules' span and without moving an event
        ahead of ``done`` or back past it. Whether the length changed; said once, and logged."""
        c, plan, model = self.config, self.config.length_plan, self.pipeline.model
        assert plan is not None
        elapsed, per_iteration = stamps[-1], statistics.median(b - a for a, b in itertools.pairwise(stamps))
        current = c.max_num_iterations
        behind = self._events_behind(current, done)

        def keeps(iterations: int) -> bool:  # the events behind stay behind, those ahead stay ahead
            return self._events_behind(iterations, done) == behind

        low = max(plan.low, *c.export_mesh_at, first_true(keeps, max(plan.low, done + 1), current))
        high = last_true(keeps, current, plan.high - 1)

        def seconds(iterations: int) -> float:
            saves = -(-iterations // c.steps_per_save) - done // c.steps_per_save
            rest = (iterations - done) * per_iteration if last else rest_seconds(c, iterations, done, per_iteration)
            return elapsed + rest + saves * plan.seconds_per_save

        iterations = max(low, last_true(lambda n: seconds(n) <= plan.train_seconds, low, high))
        c.planned_train_seconds = seconds(iterations)
        record = {"event": "replan", "step": done, "seconds_per_iteration": per_iteration, "from": current}
        append_jsonl(self.run_dir / "metrics.jsonl", {**record, "to": iterations, "planned": c.planned_train_seconds})
        if iterations == current:
            return False
        set_run_length(c, model, self.pipeline.datamanager, iterations)
        save_config(c, self.run_dir / "config.json")
        after = "its last event" if last else "its first steps"
        self.console.print(
            f"time budget {c.time_budget}: re-planned after {done} iterations at this run's own "
            f"{per_iteration:.3g} s per iteration ({after}): {current} -> {iterations} iterations, planned training "
            f"time {format_duration(c.planned_train_seconds)}; occupancy updates after {model.occupancy_steps}, "
            f"upsamples after {model.upsample_steps}"
        )
        return True

    def _train(self) -> Path:
        c = self.config
        model = self.pipeline.model
        reset_steps = [s + 1 for s in model.reset_steps()]  # the first iterations run by a rebuilt optimiser
        if self.resume_state is not None:
            optimizer = self._restore(self.resume_state, reset_steps)
        else:
            optimizer = build_optimizer(c.optimizer, model.param_groups(), self.start_step, reset_steps)
        metrics_path = self.run_dir / "metrics.jsonl"
        if self.start_step:
            drop_records_after(metrics_path, self.start_step)
        started = time.perf_counter()
        done = self.start_step
        # With --profile-phases the loop body is timed phase by phase (logging and saving excluded).
        timer = PhaseTimer() if c.profile_phases else None
        phase_totals: Counter[str] = Counter()  # update() adds the seconds of each log interval
        # On the GPU paths the metrics are read from the device once per log interval, not every step.
        read_every_step = not uses_gpu_paths(c.pipeline.model.accel, self.device)
        shown: dict[str, float] = {}
        cut_at_budget = False
        window = self._replan_window() or self._last_window()
        stamps: list[float] = []  # the clock after each iteration of the re-plan's window
        notify_started(self.observers, self.pipeline, self.run_dir, self.start_step)
        with _DeferredStop() as interrupt, contextlib.ExitStack() as bars:
            progress = bars.enter_context(TaskProgress(c.max_num_iterations, self.start_step))
            while done < c.max_num_iterations:  # a --time-budget run may set its length twice (``_replan``)
                step = done
                with timer or contextlib.nullcontext(), phase("other"):
                    optimizer, metrics, lr_scale = optimisation_step(
                        self.pipeline, optimizer, c.optimizer, step, reset_steps, c.max_num_iterations
                    )
                done = step + 1
                f_density, f_color = model.cutoffs(step)
                log_now = done % c.log_every == 0 or done == c.max_num_iterations
                if log_now or read_every_step:
                    shown = self.pipeline.read_metrics(metrics)
                    self._check_finite(done, shown)
                progress.update(done, **{k: shown[k] for k in ("loss", "psnr") if k in shown}, f=f_density)
                record = None
                if log_now:
                    record = {"step": done, **shown, "f_density": f_density, "f_color": f_color, "lr_scale": lr_scale}
                    record["elapsed_s"] = time.perf_counter() - started
                    record["rays"] = int(self.pipeline.datamanager.active.numel())
                    if timer is not None:
                        record["phases"] = timer.take()
                        phase_totals.update(record["phases"])
                    append_jsonl(metrics_path, record)
                if self.observers:
                    report = StepReport(
                        done, c.max_num_iterations, dict(shown), f_density, f_color, lr_scale,
                        time.perf_counter() - started, record, tuple(model.field.resolution),
                    )  # fmt: skip
                    notify_step(self.observers, self.pipeline, report)
                if done % c.steps_per_save == 0 or done == c.max_num_iterations:
                    self.save(done, optimizer)
                if done in c.export_mesh_at:
                    self._export_mesh(done)
                if window is not None and window.start <= done <= window.to:
                    stamps.append(self._clock(started))
                    if done == window.to:
                        if self._replan(done, stamps, window.last):
                            reset_steps = [s + 1 for s in model.reset_steps()]
                            progress.close()
                            progress = bars.enter_context(TaskProgress(c.max_num_iterations, done))
                        window, stamps = None if window.last else self._last_window(), []
                if interrupt.requested:
                    break
                if self._past_deadline(time.perf_counter() - started):
                    cut_at_budget = done < c.max_num_iterations
                    break
        elapsed = time.perf_counter() - started
        stopped_by_signal = done < c.max_num_iterations and not cut_at_budget
        notify_finished(self.observers, self.pipeline, done, interrupted=stopped_by_signal)
        if cut_at_budget and done % c.steps_per_save:  # a step on the save schedule was saved in the loop
            self.save(done, optimizer)
        elif stopped_by_signal:
            path = self.save(done, optimizer)
            name = signal.Signals(interrupt.exit_code - 128).name
            self.console.print(f"stopped by {name} at step {done}: saved {path}")
            self.console.print(f"resume with: fourierf-train {c.method_name} --load-dir {self.run_dir}")
            raise SystemExit(interrupt.exit_code)
        done_record = {"event": "done", "step": done, "train_seconds": elapsed}
        if c.planned_train_seconds is not None:
            done_record["planned_train_seconds"] = c.planned_train_seconds
        if cut_at_budget:
            done_record["planned_iterations"] = c.max_num_iterations
            done_record["fitting_iterations"] = fitting_iterations(c, done, elapsed, c.train_deadline_seconds)
        if self.device.type == "cuda":
            done_record["peak_device_memory_gb"] = torch.cuda.max_memory_allocated(self.device) / 2**30
        if timer is not None:
            phase_totals.update(timer.take())
            done_record["phases_total"] = dict(phase_totals)
        append_jsonl(metrics_path, done_record)
        self._check_alive(done, shown)
        self.console.print(
            f"trained {done - self.start_step} iterations in {format_duration(elapsed)}; run in {self.run_dir}"
        )
        if c.planned_train_seconds is not None and not self.start_step:
            planned = c.planned_train_seconds
            self.console.print(
                f"time budget {c.time_budget}: planned training time {format_duration(planned)}, actual "
                f"{format_duration(elapsed)} ({elapsed / planned - 1:+.0%})"
            )
        if cut_at_budget:
            self.console.print(
                f"[yellow]time budget {c.time_budget} reached after {done} of the {c.max_num_iterations} planned "
                f"iterations:[/yellow] training stopped and saved there, before the end of its schedules; resume with "
                f"--load-dir {self.run_dir} to finish them, or, for a whole run within the budget on this machine, "
                f"train again with --max-num-iterations {done_record['fitting_iterations']} (from this run's cost)"
            )
        if shown.get("revived_batches"):
            self.console.print(f"a dead density field was revived on {shown['revived_batches']:.0f} training batches")
        self.console.print(f"evaluate with: fourierf-eval --load-config {self.run_dir / 'config.json'}")
        return self.run_dir


START_STEPS, MIN_TIMED_STEPS = 5, 8
"""A ``--time-budget`` run's re-plan times its iterations after its first ``START_STEPS`` (allocations, first calls),
and only when at least ``MIN_TIMED_STEPS`` come before it."""
REPLAN_SHARE = 0.75
"""How far towards its first count-dependent event after its warm-up a ``--time-budget`` run plans its length again:
later times more steps, earlier leaves a shorter run room to keep that event ahead."""
LAST_TIMED_SHARE = 0.05
"""The share of a ``--time-budget`` run timed after its last event, before it plans its length a last time: enough
steps for a steady median, most of the rest left to adjust."""


class ReplanWindow(NamedTuple):
    """The iterations done over which a ``--time-budget`` run times itself, from ``start`` to ``to`` where it plans its
    length again; ``last``: once every event is behind it."""

    start: int
    to: int
    last: bool


def first_true(holds: Callable[[int], bool], low: int, high: int) -> int:
    """The least count in ``low..high`` where ``holds`` (false, then true from some count on; ``high`` if none)."""
    return low + bisect.bisect_left(range(low, high), True, key=holds)


def last_true(holds: Callable[[int], bool], low: int, high: int) -> int:
    """The greatest count in ``low..high`` where ``holds`` (true up to some count, then false; ``low - 1`` if none)."""
    return low - 1 + bisect.bisect_left(range(low, high + 1), True, key=lambda n: not holds(n))


def set_run_length(config: TrainerConfig, model: FourieRFModel, manager: DataManager, iterations: int) -> None:
    """Make ``config``'s run ``iterations`` long: its count, the settings its length plan keeps at a step (each now
    that step's fraction of the new count), and the schedules of ``model`` and ``manager`` built from its pipeline."""
    config.max_num_iterations = iterations
    for path, index, step in config.length_plan.pinned if config.length_plan else ():
        *parents, name = path.split(".")
        owner = functools.reduce(getattr, parents, config)
        value = round(step / iterations, 4)
        if index >= 0:
            value = tuple(value if i == index else v for i, v in enumerate(getattr(owner, name)))
        setattr(owner, name, value)
    model.set_run_length(iterations)
    manager.set_run_length(iterations)


@dataclass
class LengthPlan(InstantiateConfig):
    """What a ``--time-budget`` run plans its length again with, from its own speed before its first count-dependent
    event and after its last (set by ``method_configs.time_budget``)."""

    train_seconds: float
    """The training time to fill: the budget less its margin."""
    seconds_per_save: float
    low: int
    high: int
    """The counts ``low <= n < high`` the short-run rules that configured the run also cover."""
    pinned: tuple[tuple[str, int, int], ...] = ()
    """Settings a short-run rule placed at a fixed step: (config path, item of a tuple or -1, step)."""


@dataclass
class TrainerConfig(InstantiateConfig):
    """A complete training run: the method preset plus everything a user may override."""

    _target: ClassVar[type] = Trainer
    method_name: str = "fourierf-vm"
    """Name of the preset (used in the run directory)."""
    pipeline: PipelineConfig = field(default_factory=PipelineConfig)
    optimizer: OptimizerConfig = field(default_factory=OptimizerConfig)
    data: Path | None = None
    """Scene folder (copied into the dataparser's data path)."""
    data_from_run_dir: tyro.conf.Suppress[Path | None] = None
    """The scene folder relative to the run folder (set by the trainer), so a run moved together with its data
    still finds it."""
    output_dir: Path = Path("outputs")
    """Runs go to OUTPUT_DIR/<scene>/<method>/<timestamp>/."""
    max_num_iterations: int = 10000
    """Training iterations; every schedule is a fraction of this."""
    seed: int = 20211202
    """Seed of every random draw (initialisation, ray batches, jitter)."""
    device: Literal["auto", "cpu", "cuda"] = "auto"
    """Where to train: auto picks CUDA when available."""
    threads: int | None = None
    """CPU threads for torch (None: torch's default)."""
    steps_per_save: int = 1000
    """Checkpoint every N iterations (and at the end, and on Ctrl-C)."""
    keep_checkpoints: int = 3
    """How many recent checkpoints to keep."""
    log_every: int = 50
    """Append training metrics to metrics.jsonl every N iterations."""
    load_dir: Path | None = None
    """Resume the run in this directory from its latest checkpoint (its config.json is used)."""
    timestamp: str | None = None
    """Run directory name (default: the current time)."""
    export_mesh_at: tuple[int, ...] = ()
    """Export a marching-cubes mesh of the geometry after these iterations (RUN/meshes/step-N.ply)."""
    export_mesh_resolution: int = 128
    """Grid resolution of the meshes exported during training."""
    profile_phases: bool = False
    """Time each phase of every iteration (filtering, sampling, field, backward, ...) into metrics.jsonl."""
    viewer: bool = False
    """Serve the web viewer during training (pip install 'fourierf[viewer]'): the scene as it forms, at a capped
    render rate so training slows by at most about ``viewer_max_slowdown``."""
    viewer_port: int = 7007
    """Port of the web viewer (the next free one is taken, and said, when it is in use)."""
    viewer_host: str = "127.0.0.1"
    """Interface the web viewer listens on: 127.0.0.1 is this machine only; 0.0.0.0 (every interface) lets other
    machines open the page, which has no password."""
    viewer_max_slowdown: float = 0.03
    """The share of training time the live viewer's snapshots, renders and meshes may take (0.03: 3 %). Each picture
    also costs the browser: on a 2-core CPU with the browser on it, training slowed by about twice this share plus the
    browser's idle drawing (BENCHMARKS.md, "Web viewer")."""
    vis: Literal["none", "tensorboard"] = "none"
    """Also log to TensorBoard under RUN/tensorboard (pip install 'fourierf[tensorboard]')."""
    vis_image_every: int = 500
    """With --vis tensorboard: render one training and one held-out view every N iterations."""
    scene_preset: Literal["auto", "synthetic", "real"] = "auto"
    """Synthetic or real-scene settings; auto picks real for forward-facing scenes (flags you set always win)."""
    budget_rule: bool = True
    """Runs shorter than the paper's 10k iterations get the values chosen on validation views for short runs
    (docs/defaults.md, one section per rule); False keeps the preset's values at any budget."""
    time_budget: str | None = None
    """Train for this long (90s, 5m, 1.5h, 1h30m) instead of a set iteration count: timing a few steps first, the
    run picks the count that ends training within it (setup and evaluation not included), picks it again from its
    own speed before its first event and after its last, and stops there should the iterations cost more than planned;
    every schedule stays a fraction of the run. Not with --max-num-iterations, nor on resume."""
    planned_train_seconds: tyro.conf.Suppress[float | None] = None
    """The training time a --time-budget run planned (set by finalize), compared with the actual one at the end."""
    length_plan: tyro.conf.Suppress[LengthPlan | None] = None
    """How a --time-budget run plans its length again from its own speed once it trains (set by finalize)."""
    train_deadline_seconds: tyro.conf.Suppress[float | None] = None
    """A --time-budget run's training stops and saves here, iterations left or not: an iteration's cost follows the
    field's state (lit, pruned), so the plan is an estimate and the budget a promise."""
