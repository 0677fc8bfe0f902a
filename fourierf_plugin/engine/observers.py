"""What watches a training run from outside its loop: the live web viewer, TensorBoard.

The trainer tells each observer what happened after every step; an observer reads the pipeline (to render, to log)
but never changes it nor the trainer's state, so data still flows one way. The trainer is handed its observers (it
never imports the viewer or TensorBoard, which sit above it): ``scripts.observers.build_observers`` makes the ones a
config asks for.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any, Protocol

if TYPE_CHECKING:
    from fourierf_plugin.pipelines.base import Pipeline


@dataclass(frozen=True)
class StepReport:
    """One finished iteration as the trainer saw it."""

    step: int
    """Iterations done (1 after the first)."""
    max_steps: int
    metrics: dict[str, float]
    """The latest metrics read from the device (loss, psnr, ...): read every step on a CPU, once per log interval
    on the GPU paths (then they may be a few steps old)."""
    f_density: float
    f_color: float
    lr_scale: float
    elapsed_s: float
    """Training seconds since this process started the loop."""
    record: dict[str, Any] | None = None
    """The metrics.jsonl record when this step was logged (it then holds phases, rays, ...), else None."""
    resolution: Sequence[int] = field(default_factory=tuple)
    """The field's grid vertices per axis now."""


class TrainingObserver(Protocol):
    """A passive watcher of a run (the trainer calls these in order; exceptions are the observer's own to report)."""

    def started(self, pipeline: Pipeline, run_dir: Path, start_step: int) -> None: ...

    def step_done(self, pipeline: Pipeline, report: StepReport) -> None: ...

    def finished(self, pipeline: Pipeline, step: int, interrupted: bool) -> None: ...


def notify_started(observers: Sequence[TrainingObserver], pipeline: Pipeline, run_dir: Path, start: int) -> None:
    for observer in observers:
        observer.started(pipeline, run_dir, start)


def notify_step(observers: Sequence[TrainingObserver], pipeline: Pipeline, report: StepReport) -> None:
    for observer in observers:
        observer.step_done(pipeline, report)


def notify_finished(observers: Sequence[TrainingObserver], pipeline: Pipeline, step: int, interrupted: bool) -> None:
    for observer in observers:
        observer.finished(pipeline, step, interrupted)
