"""``--viewer`` during training: the page is served and draws snapshots, and training is exactly what it was without."""

from __future__ import annotations

import json
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
    """Also: every picture is made on the training thread (a second thread computing with torch would give OpenMP a
    second worker team, which slows every later training step on a CPU: ``viewer.live``)."""
    require_module("viser", VISER_WHY)
    from fourierf_plugin.viewer import server as server_module
    from fourierf_plugin.viewer.live import LiveViewer

    drawn_on: list[threading.Thread] = []
    real_render = server_module.render_view

    def recorded(*args, **kwargs):
        drawn_on.append(threading.current_thread())
        return real_render(*args, **kwargs)

    monkeypatch.setattr(server_module, "render_view", recorded)

    plain = Trainer(tiny_trainer_config(tmp_path / "plain", iters=ITERS))
    plain_dir = plain.train()

    viewer = LiveViewer(port=0, max_slowdown=1.0, host="127.0.0.1")  # no cap: as much interference as possible
    browser = BrowserAtStart(viewer)
    watched = Trainer(tiny_trainer_config(tmp_path / "watched", iters=ITERS), observers=[viewer, browser])
    watched_dir = watched.train()

    assert browser.page is not None and "<html" in browser.page.lower()
    assert viewer.snapshots >= 1
    images = browser.client.scene.images
    assert images, "the render thread drew nothing for the connected browser"
    height, width = images[-1].shape[:2]
    assert max(height, width) in (128, 384)  # the live preview or final size
    assert viewer.view is not None and viewer.view.viewed.progress.finished
    assert drawn_on and set(drawn_on) == {threading.current_thread()}, "a picture was made off the training thread"

    assert _records(watched_dir) == _records(plain_dir)
    plain_state, watched_state = plain.pipeline.model.state_dict(), watched.pipeline.model.state_dict()
    assert plain_state.keys() == watched_state.keys()
    for name, value in plain_state.items():
        assert torch.equal(value, watched_state[name]), name


def test_the_live_viewer_stops_its_page_at_the_end(tmp_path: Path) -> None:
    require_module("viser", VISER_WHY)
    from fourierf_plugin.viewer.live import LiveViewer

    viewer = LiveViewer(port=0, max_slowdown=0.1, host="127.0.0.1")
    Trainer(tiny_trainer_config(tmp_path, iters=5), observers=[viewer]).train()
    deadline = time.monotonic() + 10
    while time.monotonic() < deadline:
        try:
            urllib.request.urlopen(f"http://127.0.0.1:{viewer.port}/", timeout=1).close()
        except OSError:
            break
        time.sleep(0.2)
    else:
        pytest.fail("the page still answers after training ended")


def test_a_slowdown_outside_0_1_is_a_user_error() -> None:
    require_module("viser", VISER_WHY)
    from fourierf_plugin.viewer.live import LiveViewer

    with pytest.raises(UserError, match="viewer-max-slowdown"):
        LiveViewer(port=0, max_slowdown=0.0)
