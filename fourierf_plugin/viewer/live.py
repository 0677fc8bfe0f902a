"""``fourierf-train ... --viewer True``: the web page during training, drawn from snapshots of the parameters.

The training thread only ever copies the weights (``state_dict`` clones, when a browser is connected, the renderer
is idle and the budget allows); a private second model loads that copy in the render thread and draws from it, so
the optimiser never shares a tensor with a render and a render never waits on a step. Copies and renders together
are held under ``max_slowdown`` of the wall time (:class:`RenderBudget`).
"""

from __future__ import annotations

import threading
import time
from pathlib import Path
from typing import TYPE_CHECKING

import torch
from torch import Tensor

from fourierf_plugin.engine.observers import StepReport
from fourierf_plugin.utils.console import warn
from fourierf_plugin.utils.errors import fail
from fourierf_plugin.viewer.render_budget import RenderBudget
from fourierf_plugin.viewer.scene_view import held_out_views
from fourierf_plugin.viewer.server import ViewerServer, ViewerSettings, open_server, require_viser
from fourierf_plugin.viewer.viewed_run import TrainingProgress, ViewedRun

if TYPE_CHECKING:
    from fourierf_plugin.models.fourierf import FourieRFModel
    from fourierf_plugin.pipelines.base import Pipeline

LIVE_SETTINGS = ViewerSettings(preview_side=128, final_side=384, render_threads=1)
"""Smaller pictures than for a saved run, rendered on one core: every render second is taken from training."""


def snapshot(model: FourieRFModel) -> dict[str, Tensor]:
    """A copy of every parameter and buffer, detached (nothing the optimiser will touch again)."""
    return {name: value.detach().clone() for name, value in model.state_dict().items()}


def render_model(pipeline: Pipeline) -> FourieRFModel:
    """A second model of the run's configuration, for snapshots to be loaded into.

    Built from its own generator, so the run's random streams draw nothing for it."""
    scene = pipeline.datamanager.reference_outputs
    model = pipeline.model
    copy: FourieRFModel = pipeline.config.model.setup(
        scene_box=scene.scene_box.to(pipeline.device),
        near=scene.near,
        far=scene.far,
        effects=pipeline.effects,
        max_iters=model.max_iters,
        generator=torch.Generator().manual_seed(0),
        device=pipeline.device,
    ).to(pipeline.device)
    return copy.eval()


class LiveViewer:
    """A :class:`~fourierf_plugin.engine.observers.TrainingObserver` that serves the page while the run trains."""

    def __init__(self, port: int, max_slowdown: float, host: str = "0.0.0.0") -> None:
        """Opens the server at once (before the run folder exists), so a missing extra or an unusable port stops
        the run before anything is written."""
        if not 0 < max_slowdown <= 1:
            fail(f"--viewer-max-slowdown {max_slowdown} must be in (0, 1]", "use e.g. 0.1 (training 10 % slower)")
        require_viser()
        self.budget = RenderBudget(max_slowdown)
        self.server = open_server(port, host)
        self.port = int(self.server.get_port())
        self.view: ViewerServer | None = None
        """The page's content while it is updated (None before ``started`` and after a failure)."""
        self._page: ViewerServer | None = None
        self._stopped = False
        self.snapshots = 0
        self._pending: tuple[dict[str, Tensor], int] | None = None
        self._pending_lock = threading.Lock()

    # -- the observer protocol ---------------------------------------------------------------------------------------
    def started(self, pipeline: Pipeline, run_dir: Path, start_step: int) -> None:
        model = render_model(pipeline)
        progress = TrainingProgress(start_step, start_step)
        viewed = ViewedRun(model, start_step, run_dir, progress)
        viewed.load_snapshot(snapshot(pipeline.model), start_step)
        datamanager = pipeline.datamanager
        view = ViewerServer(self.server, viewed, datamanager.reference_outputs, None, LIVE_SETTINGS, self.budget)
        self.view = self._page = view
        # Reading the test images takes seconds on a real scene: not on the training thread.
        threading.Thread(
            target=lambda: view.show_test_views(held_out_views(datamanager.parser)),
            name="fourierf-viewer-test-views",
            daemon=True,
        ).start()

    def step_done(self, pipeline: Pipeline, report: StepReport) -> None:
        try:
            self._step_done(pipeline, report)
        except Exception as err:  # the page is a convenience: training goes on without it
            warn(f"the live viewer stops updating: {err}")
            self.view = None

    def _step_done(self, pipeline: Pipeline, report: StepReport) -> None:
        view = self.view
        if view is None:
            return
        progress = view.viewed.progress
        assert progress is not None
        progress.step, progress.max_steps, progress.metrics = report.step, report.max_steps, report.metrics
        progress.f_density, progress.f_color = report.f_density, report.f_color
        if not self._wants_snapshot(view):
            return
        started = time.perf_counter()
        state = snapshot(pipeline.model)
        self.budget.charge(started, time.perf_counter() - started)
        with self._pending_lock:
            self._pending = (state, report.step)
        self.snapshots += 1
        threading.Thread(target=self._load_pending, name="fourierf-viewer-snapshot", daemon=True).start()

    def finished(self, pipeline: Pipeline, step: int, interrupted: bool) -> None:
        """Close the page with the run (Ctrl-C included)."""
        if self._stopped:
            return
        self._stopped = True
        if self._page is None:
            self.server.stop()
            return
        progress = self._page.viewed.progress
        assert progress is not None
        progress.finished = True
        self._page.stop()

    # -- snapshots ----------------------------------------------------------------------------------------------------
    def _wants_snapshot(self, view: ViewerServer) -> bool:
        """Someone is watching, the last snapshot is loaded, and the budget allows the copy and a render."""
        with self._pending_lock:
            busy = self._pending is not None
        return not busy and view.client_count > 0 and self.budget.wait_seconds() == 0

    def _load_pending(self) -> None:
        """Load the snapshot into the render model (off the training thread) and ask for a new picture."""
        view = self.view
        with self._pending_lock:
            pending = self._pending
        if view is None or pending is None:
            return
        state, step = pending
        started = time.perf_counter()
        view.viewed.load_snapshot(state, step)
        self.budget.charge(started, time.perf_counter() - started)
        view.follow_run_cutoffs()
        view.refresh_status()
        view.changed(moving=False)
        with self._pending_lock:
            self._pending = None
