"""``--viewer`` during training: the page is served and draws snapshots, and training is exactly what it was without."""

from __future__ import annotations

import json
import os
import signal
import threading
import time
import urllib.request
from pathlib import Path

import pytest
import torch

from fourierf_plugin.engine.observers import StepReport
from fourierf_plugin.engine.trainer import Trainer
from fourierf_plugin.pipelines.base import Pipeline
from fourierf_plugin.utils.errors import UserError
from tests.conftest import require_module
from tests.helpers import tiny_trainer_config
from tests.viewer.fake_client import FakeClient

pytestmark = pytest.mark.slow

ITERS = 60
VISER_WHY = "the live viewer needs viser (pip install '.[viewer]')"


class BrowserAtStart:
    """Connects a fake browser to the live viewer as training starts and fetches the page once, mid-run."""

    def __init__(self, viewer) -> None:
        self.viewer = viewer
        self.client = FakeClient()
        self.page: str | None = None

    def started(self, pipeline: Pipeline, run_dir: Path, start_step: int) -> None:
        self.viewer.view.connect(self.client)
        self.client.camera.move_to(pipeline.datamanager.reference_outputs.cameras, 0)

    def step_done(self, pipeline: Pipeline, report: StepReport) -> None:
        if report.step == ITERS // 2:
            with urllib.request.urlopen(f"http://127.0.0.1:{self.viewer.port}/", timeout=10) as response:
                self.page = response.read().decode()
            # The viewer draws between steps, on this thread: by now a picture has been sent.
            self.client.scene.received.wait(timeout=20)

    def finished(self, pipeline: Pipeline, step: int, interrupted: bool) -> None:
        pass


def _records(run_dir: Path) -> list[dict]:
    """metrics.jsonl without the wall-clock fields (which differ between any two runs)."""
    records = [json.loads(line) for line in (run_dir / "metrics.jsonl").read_text().splitlines()]
    return [{k: v for k, v in r.items() if k not in ("elapsed_s", "train_seconds")} for r in records]


def test_the_live_viewer_draws_snapshots_and_leaves_training_unchanged(tmp_path: Path, monkeypatch) -> None:
    """Also: every picture during training is made on the training thread (a second thread computing with torch
    would give OpenMP a second worker team, which slows every later training step on a CPU: ``viewer.live``)."""
    require_module("viser", VISER_WHY)
    from fourierf_plugin.viewer import server as server_module
    from fourierf_plugin.viewer.live import LiveViewer

    drawn_on: list[threading.Thread] = []
    real_render = server_module.render_view

    def recorded(*args, **kwargs):
        if not viewer._stopped:  # during training (the finished page has its own render thread)
            drawn_on.append(threading.current_thread())
        return real_render(*args, **kwargs)

    monkeypatch.setattr(server_module, "render_view", recorded)

    plain = Trainer(tiny_trainer_config(tmp_path / "plain", iters=ITERS))
    plain_dir = plain.train()

    viewer = LiveViewer(port=0, max_slowdown=1.0, host="127.0.0.1")  # no cap: as much interference as possible
    browser = BrowserAtStart(viewer)
    watched = Trainer(tiny_trainer_config(tmp_path / "watched", iters=ITERS), observers=[viewer, browser])
    watched_dir = watched.train()
    viewer.close()

    assert browser.page is not None and "<html" in browser.page.lower()
    assert viewer.snapshots >= 1
    images = browser.client.scene.images
    assert images, "the render thread drew nothing for the connected browser"
    height, width = images[-1].shape[:2]
    settings = viewer.view.settings
    assert max(height, width) in (settings.preview_side, settings.final_side)  # shown at the preview or final size
    assert settings.final_side == 100, "the final size is the training images' (100 px)"
    assert viewer.view is not None and viewer.view.viewed.progress.finished
    assert drawn_on and set(drawn_on) == {threading.current_thread()}, "a picture was made off the training thread"

    assert _records(watched_dir) == _records(plain_dir)
    plain_state, watched_state = plain.pipeline.model.state_dict(), watched.pipeline.model.state_dict()
    assert plain_state.keys() == watched_state.keys()
    for name, value in plain_state.items():
        assert torch.equal(value, watched_state[name]), name


def _answers(port: int) -> bool:
    try:
        urllib.request.urlopen(f"http://127.0.0.1:{port}/", timeout=1).close()
    except OSError:
        return False
    return True


def test_at_the_end_the_page_shows_the_finished_run_until_closed(tmp_path: Path) -> None:
    require_module("viser", VISER_WHY)
    from fourierf_plugin.viewer.live import LiveViewer

    viewer = LiveViewer(port=0, max_slowdown=0.1, host="127.0.0.1")
    browser = BrowserAtStart(viewer)
    trainer = Trainer(tiny_trainer_config(tmp_path, iters=5), observers=[viewer, browser])
    trainer.train()
    try:
        page = viewer.view
        assert page is not None and _answers(viewer.port), "the page closed with the run"
        assert "finished at step 5" in page.status.content
        assert page.viewed.step == 5 and page.live_pacer is None and page._thread is not None  # a saved run's page
        drawn = len(browser.client.scene.images)
        browser.client.camera.move_to(trainer.pipeline.datamanager.reference_outputs.cameras, 1)
        assert _wait_for(lambda: len(browser.client.scene.images) > drawn), "the finished page draws no new view"
    finally:
        viewer.after_training(None)  # not at a terminal: closes the page
    assert _wait_for(lambda: not _answers(viewer.port)), "the page still answers after it was closed"


class CtrlCAt:
    """Presses Ctrl-C (SIGINT to this process) after a given step, as a user at the terminal would."""

    def __init__(self, step: int) -> None:
        self.step = step

    def started(self, pipeline: Pipeline, run_dir: Path, start_step: int) -> None:
        pass

    def step_done(self, pipeline: Pipeline, report: StepReport) -> None:
        if report.step == self.step:
            os.kill(os.getpid(), signal.SIGINT)

    def finished(self, pipeline: Pipeline, step: int, interrupted: bool) -> None:
        pass


def test_ctrl_c_is_shown_on_the_page_which_stays_open(tmp_path: Path) -> None:
    require_module("viser", VISER_WHY)
    from fourierf_plugin.viewer.live import LiveViewer

    viewer = LiveViewer(port=0, max_slowdown=0.1, host="127.0.0.1")
    trainer = Trainer(tiny_trainer_config(tmp_path, iters=50), observers=[viewer, BrowserAtStart(viewer), CtrlCAt(3)])
    try:
        with pytest.raises(SystemExit) as stop:
            trainer.train()
        assert stop.value.code == 130
        page = viewer.view
        assert page is not None and _answers(viewer.port), "the page closed on Ctrl-C"
        assert "stopped (interrupted) at step 3" in page.status.content and page.viewed.step == 3
    finally:
        viewer.after_training(130)  # not at a terminal: closes the page
    assert _wait_for(lambda: not _answers(viewer.port)), "the page still answers after it was closed"


def _wait_for(condition, seconds: float = 20.0) -> bool:
    deadline = time.monotonic() + seconds
    while time.monotonic() < deadline:
        if condition():
            return True
        time.sleep(0.1)
    return False


def test_a_slowdown_outside_0_1_is_a_user_error() -> None:
    require_module("viser", VISER_WHY)
    from fourierf_plugin.viewer.live import LiveViewer

    with pytest.raises(UserError, match="viewer-max-slowdown"):
        LiveViewer(port=0, max_slowdown=0.0)
