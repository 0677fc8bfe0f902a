"""``fourierf-train ... --viewer True``: the web page during training, drawn from snapshots of the parameters.

A private second model loads a copy of the weights (``state_dict`` clones) and draws from it, so the optimiser never
shares a tensor with a render. Copies, renders and meshes are made on the training thread itself, between two steps,
when a browser is connected and the budget allows: together they take at most ``max_slowdown`` of the wall time
(:class:`RenderBudget`), which is then the training's slowdown.

Why not a render thread beside the training: on a CPU it costs far more than its own time. torch's OpenMP (libgomp)
gives every thread that runs a parallel op its own team of worker threads; once the workers outnumber the cores,
libgomp stops spinning at barriers and every parallel op of the training pays futex wake-ups, for the rest of the
process. On 2 cores a render thread with 2 threads slowed P-CPU training by ~50 % at a 10 % render budget (the cores
stood idle a quarter of the time); with 1 thread its renders oversubscribed the cores and stalled the step's OpenMP
threads (+19-43 %). viser's callbacks only record what the browser did; the page's work waits for the next step.

What the page shows costs accordingly: the status (step, cutoffs, loss, PSNR) is refreshed every
``STATUS_SECONDS`` whatever the budget (it is a line of text); each picture is sized to cost the budget's share of
``PICTURE_SECONDS`` (scaled up on the page), so pictures come at a steady rate and the cutoff ramp is seen forming.
When the run ends (Ctrl-C included) the page says so and carries on as a saved run's on the final weights.
"""

from __future__ import annotations

import sys
import threading
import time
from pathlib import Path
from typing import TYPE_CHECKING

import torch
from torch import Tensor

from fourierf_plugin.engine.observers import StepReport
from fourierf_plugin.utils.console import get_console, warn
from fourierf_plugin.utils.errors import fail
from fourierf_plugin.viewer.render_budget import RenderBudget
from fourierf_plugin.viewer.render_service import PreviewQuality
from fourierf_plugin.viewer.scene_view import held_out_views
from fourierf_plugin.viewer.server import ViewerServer, ViewerSettings, open_server, require_viser, served_url
from fourierf_plugin.viewer.viewed_run import TrainingProgress, ViewedRun

if TYPE_CHECKING:
    from fourierf_plugin.models.fourierf import FourieRFModel
    from fourierf_plugin.pipelines.base import Pipeline

PICTURE_SECONDS = 1.0
"""The time between two pictures of the live page at its budget (each picture costs the budget's share of it)."""
STATUS_SECONDS = 0.5
"""The longest the page's status text waits for a refresh during training."""


def live_settings(max_slowdown: float) -> ViewerSettings:
    """Smaller pictures than for a saved run, marched as previews are, each costing ``max_slowdown`` of
    ``PICTURE_SECONDS``: every render second is taken from training."""
    return ViewerSettings(
        preview_side=128,
        preview_seconds=0.1,
        final_quality=PreviewQuality(),
        picture_seconds=max_slowdown * PICTURE_SECONDS,
    )


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

    def __init__(self, port: int, max_slowdown: float, host: str = "127.0.0.1") -> None:
        """Opens the server at once (before the run folder exists), so a missing extra or an unusable port stops
        the run before anything is written."""
        if not 0 < max_slowdown <= 1:
            fail(
                f"--viewer-max-slowdown {max_slowdown} must be in (0, 1]",
                "use e.g. 0.03 (the viewer takes 3 % of the training time)",
            )
        require_viser()
        self.budget = RenderBudget(max_slowdown)
        self.server = open_server(port, host)
        self.port = int(self.server.get_port())
        self.view: ViewerServer | None = None
        """The page's content while it is updated (None before ``started`` and after a failure)."""
        self._page: ViewerServer | None = None
        self._stopped = False
        self.snapshots = 0
        self._elapsed = 0.0
        self._status_at = 0.0
        self.status_refreshes = 0

    # -- the observer protocol ---------------------------------------------------------------------------------------
    def started(self, pipeline: Pipeline, run_dir: Path, start_step: int) -> None:
        model = render_model(pipeline)
        progress = TrainingProgress(start_step, model.max_iters, {}, *pipeline.model.cutoffs(start_step))
        viewed = ViewedRun(model, start_step, run_dir, progress)
        viewed.load_snapshot(snapshot(pipeline.model), start_step)
        datamanager = pipeline.datamanager
        view = ViewerServer(
            self.server, viewed, datamanager.reference_outputs, None, live_settings(self.budget.max_share or 1.0),
            render_thread=False,
        )  # fmt: skip
        self.view = self._page = view

        def show_test_views() -> None:
            torch.set_num_threads(1)  # no OpenMP team of its own (module docstring)
            view.show_test_views(held_out_views(datamanager.parser))

        # Reading the test images takes seconds on a real scene: not on the training thread.
        threading.Thread(target=show_test_views, name="fourierf-viewer-test-views", daemon=True).start()

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
        if view.viewed.model.max_iters != report.max_steps:  # a --time-budget run planned its length again
            view.viewed.model.set_run_length(report.max_steps)
        self._elapsed = report.elapsed_s
        if view.client_count == 0:
            return
        started = time.perf_counter()
        if started - self._status_at >= STATUS_SECONDS:  # whatever the budget: a line of text
            view.refresh_status()
            self._status_at = started
            self.status_refreshes += 1
        if self.budget.wait_seconds() > 0:
            self.budget.charge(started, time.perf_counter() - started)
            return
        pictures = view.renders
        if view.viewed.step != report.step:  # every picture shows the newest weights (the ramp as it happens)
            self._load_snapshot(view, pipeline, report.step)
        view.do_due_work()
        cost = time.perf_counter() - started
        self.budget.charge(started, cost)
        if view.renders > pictures and view.live_pacer is not None and view.last_render_seconds is not None:
            view.live_pacer.observe_overhead(cost - view.last_render_seconds)

    def finished(self, pipeline: Pipeline, step: int, interrupted: bool) -> None:
        """The run ended (Ctrl-C included): the page says so and shows the final weights as a saved run's page,
        until :meth:`close`."""
        if self._stopped:
            return
        self._stopped = True
        spent, elapsed = self.budget.spent_seconds, self._elapsed
        share = f" ({100 * spent / elapsed:.1f} % of {elapsed:.0f} s)" if elapsed > 0 else ""
        get_console().print(
            f"live viewer: {self.snapshots} snapshots, {self._page.renders if self._page else 0} pictures, "
            f"{spent:.1f} s of the training's time{share}"
        )
        page = self._page
        if page is None:
            self.close()
            return
        try:
            progress = page.viewed.progress
            assert progress is not None
            progress.step, progress.finished, progress.interrupted = step, True, interrupted
            progress.f_density, progress.f_color = page.viewed.model.cutoffs(step)
            self._load_snapshot(page, pipeline, step)
            page.become_saved_run()
            self.view = page
        except Exception as err:  # the page is a convenience: the run's end must not fail because of it
            warn(f"the live viewer closes: {err}")
            self.close()

    def close(self) -> None:
        """Stop the page (idempotent)."""
        self._stopped = True
        if self._page is not None:
            self._page.stop()
        else:
            self.server.stop()

    def after_training(self, exit_code: int | None) -> None:
        """Once training has returned (``exit_code`` None) or stopped on a signal: keep showing the finished run
        until Ctrl-C when a user is at the terminal and the run ended by itself or by Ctrl-C (130; another signal is
        a scheduler's or a closed terminal's), else close the page."""
        if self._page is None or not sys.stdin.isatty() or exit_code not in (None, 130):
            self.close()
            return
        url = served_url(self._page.server.get_host(), self.port)
        get_console().print(f"the viewer keeps showing the finished run at {url}: Ctrl-C closes it")
        try:
            while True:
                time.sleep(1.0)
        except KeyboardInterrupt:
            pass
        finally:
            self.close()

    # -- snapshots ----------------------------------------------------------------------------------------------------
    def _load_snapshot(self, view: ViewerServer, pipeline: Pipeline, step: int) -> None:
        """Copy the training weights into the page's model and mark the page out of date."""
        view.viewed.load_snapshot(snapshot(pipeline.model), step)
        self.snapshots += 1
        view.follow_run_cutoffs()
        view.refresh_status()
        view.changed(moving=False)
