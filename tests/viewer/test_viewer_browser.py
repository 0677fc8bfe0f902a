"""The viewer in a real headless browser: the page loads, the render is drawn, a cutoff of 0 makes it smoother; a
live run's page shows the curriculum forming and its end; on a saved run, keyframes added on the page make a
camera path that ``fourierf-render camera-path`` renders.

Debian's chromium driven by playwright (no browser download). Outside CI the tests skip when playwright, viser or
chromium is missing; in CI (which installs them) they fail instead. Every wait is on a condition with a generous
timeout: CI runs them on two shared cores.
"""

from __future__ import annotations

import hashlib
import io
import json
import re
import threading
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

from fourierf_plugin.engine.trainer import Trainer
from fourierf_plugin.scripts.render import main as render_main
from fourierf_plugin.scripts.viewer import ViewerConfig, ViewerHandle, serve
from fourierf_plugin.viewer.headless import CHROMIUM, CHROMIUM_ARGS
from fourierf_plugin.viewer.render_service import high_frequency_energy
from tests.conftest import require_module, skip_outside_ci
from tests.helpers import tiny_trainer_config

pytestmark = pytest.mark.slow

VIEWPORT = {"width": 960, "height": 640}
LIVE_ITERS = 300
RAMP = ["--pipeline.model.fourier.ramp-fraction", "0.8"]
"""The band opens over most of the tiny run, so the ramp lasts long enough to be watched on a fast machine too."""


def require_browser():
    """playwright's sync API and chromium's path (a skip outside CI when either is missing)."""
    require_module("viser", "the viewer needs viser (pip install '.[viewer]')")
    sync_api = require_module("playwright.sync_api", "the browser test needs playwright (pip install playwright)")
    if not CHROMIUM.exists():
        skip_outside_ci(f"{CHROMIUM} is absent: install Debian's chromium package to run the browser test")
    return sync_api, CHROMIUM


def _wait(condition: Callable[[], bool], seconds: float, what: str) -> None:
    deadline = time.monotonic() + seconds
    while not condition():
        if time.monotonic() > deadline:
            pytest.fail(f"timed out after {seconds:.0f} s waiting for {what}")
        time.sleep(0.1)


def render_area(screenshot: bytes) -> np.ndarray:
    """The middle of the 3D view (left of the control panel), where the background render shows, as RGB."""
    image = np.asarray(Image.open(io.BytesIO(screenshot)).convert("RGB"), dtype=np.float64)
    height, width = image.shape[:2]
    return image[height // 4 : 3 * height // 4, width // 8 : width // 2]


def settled_screenshot(page, handle: ViewerHandle, renders_before: int) -> np.ndarray:
    """A screenshot once a new final picture has been sent and had time to reach the page."""
    _wait(lambda: handle.view.final_renders > renders_before, 40, "the final render")
    time.sleep(1.5)
    return render_area(page.screenshot())


def _open(playwright, chromium: Path, url: str):
    browser = playwright.chromium.launch(executable_path=str(chromium), args=list(CHROMIUM_ARGS))
    page = browser.new_page(viewport=VIEWPORT)
    page.goto(url, wait_until="load", timeout=60_000)
    return browser, page


def test_the_page_shows_the_render_and_a_zero_cutoff_smooths_it(trained_run) -> None:
    sync_api, chromium = require_browser()
    _, run_dir = trained_run
    cfg = ViewerConfig(load_config=run_dir / "config.json", port=0, host="127.0.0.1", preview_side=64, final_side=256)
    handle = serve(cfg)
    try:
        with sync_api.sync_playwright() as playwright:
            browser, page = _open(playwright, chromium, handle.url)
            try:
                _wait(lambda: handle.view.client_count > 0, 60, "the page to connect")  # a cold chromium start
                full = settled_screenshot(page, handle, 0)
                assert full.var() > 100.0, f"the render area is flat (variance {full.var():.1f}): nothing was drawn"

                before = handle.view.final_renders
                handle.view.density_slider.value = 0.0
                handle.view.color_slider.value = 0.0
                coarse = settled_screenshot(page, handle, before)
                _wait(lambda: "nearly blank" in page.inner_text("body"), 30, "the hint at cutoff 0")
            finally:
                browser.close()
    finally:
        handle.stop()
    assert not np.array_equal(full, coarse)
    energies = high_frequency_energy(coarse), high_frequency_energy(full)
    assert energies[0] < 0.8 * energies[1], f"high-frequency energy at cutoff 0 vs 1: {energies}"


# -- a live run -------------------------------------------------------------------------------------------------------
STATUS_RE = re.compile(r"training step (\d+) / \d+.*?run cutoffs density ([0-9.]+)", re.S)

WATCH_STATUS_JS = """() => {
  window.__status = [];
  const record = () => {
    const m = document.body.innerText.match(/training step (\\d+) \\//);
    const last = window.__status[window.__status.length - 1];
    if (m && (!last || last[1] !== +m[1])) window.__status.push([performance.now(), +m[1]]);
  };
  new MutationObserver(record).observe(document.body, {subtree: true, childList: true, characterData: true});
  record();
}"""
"""Records in the page itself each status step it shows and when (so the test's own polling rate does not matter)."""


class PageWatcher(threading.Thread):
    """A browser on the live page, from another thread while training runs on this one: it records the status
    steps the page shows (with the page's own clock) and the distinct pictures of the render area while the run's
    density cutoff is below 1, until the page says the run finished."""

    def __init__(self, sync_api, chromium: Path, port: int) -> None:
        super().__init__(name="page-watcher", daemon=True)
        self.sync_api, self.chromium, self.port = sync_api, chromium, port
        self.ramp_pictures: set[str] = set()
        self.status: list[tuple[float, int]] = []
        self.finished_text = ""
        self.error: BaseException | None = None
        self.connected = threading.Event()
        self.stop = threading.Event()

    def run(self) -> None:
        try:
            with self.sync_api.sync_playwright() as playwright:
                browser, page = _open(playwright, self.chromium, f"http://127.0.0.1:{self.port}")
                try:
                    self._watch(page)
                finally:
                    browser.close()
        except BaseException as err:  # reported by the test
            self.error = err

    def _watch(self, page) -> None:
        page.wait_for_function("() => /training step/.test(document.body.innerText)", timeout=120_000)
        page.evaluate(WATCH_STATUS_JS)
        self.connected.set()
        while not self.stop.is_set():
            text = page.inner_text("body")
            if "finished at step" in text:
                self.finished_text = text
                time.sleep(2.0)  # the finished page goes on drawing: leave it a moment
                self.finished_text = page.inner_text("body")
                break
            match = STATUS_RE.search(text)
            if match and float(match.group(2)) < 1.0:
                shot = page.screenshot(type="jpeg", quality=90)
                area = render_area(shot)
                if area.var() > 1.0:  # a picture, not the empty page
                    self.ramp_pictures.add(hashlib.sha1(np.round(area / 8).tobytes()).hexdigest())
            time.sleep(0.2)
        self.status = [(t / 1000.0, step) for t, step in page.evaluate("() => window.__status")]


class WaitForBrowser:
    """Holds the first training step until the watching browser is on the page (a cold chromium start takes
    seconds on a loaded machine; the run must not be over before it looks)."""

    def __init__(self, watcher: PageWatcher) -> None:
        self.watcher = watcher

    def started(self, pipeline, run_dir, start_step) -> None:
        pass

    def step_done(self, pipeline, report) -> None:
        if report.step == 1 and not self.watcher.connected.wait(180):
            pytest.fail("the browser never showed the live page")

    def finished(self, pipeline, step, interrupted) -> None:
        pass


def test_the_live_page_shows_the_curriculum_forming_and_the_run_ending(tmp_path: Path) -> None:
    sync_api, chromium = require_browser()
    from fourierf_plugin.viewer.live import LiveViewer

    viewer = LiveViewer(port=0, max_slowdown=0.05, host="127.0.0.1")
    watcher = PageWatcher(sync_api, chromium, viewer.port)
    config = tiny_trainer_config(tmp_path, iters=LIVE_ITERS, extra=RAMP)
    try:
        trainer = Trainer(config, observers=[viewer, WaitForBrowser(watcher)])
        watcher.start()
        trainer.train()
        _wait(lambda: not watcher.is_alive() or bool(watcher.finished_text), 120, "the page to show the end")
        watcher.stop.set()
        watcher.join(120)
    finally:
        watcher.stop.set()
        viewer.close()
    if watcher.error is not None:
        raise watcher.error

    assert f"finished at step {LIVE_ITERS}" in watcher.finished_text
    assert "Connecting" not in watcher.finished_text, "the finished page lost its server"
    assert len(watcher.ramp_pictures) >= 5, f"{len(watcher.ramp_pictures)} distinct pictures while the band opened"
    times = [t for t, _ in watcher.status]
    steps = [s for _, s in watcher.status]
    assert steps == sorted(steps) and len(steps) >= 3, f"the status steps shown: {steps}"
    gaps = np.diff(times)
    span = times[-1] - times[0]
    assert len(steps) - 1 >= span - 1.0, f"{len(steps)} status updates in {span:.1f} s: fewer than one a second"
    assert gaps.max() < 3.0, f"the status stood still for {gaps.max():.1f} s"


# -- a camera path made on the page -----------------------------------------------------------------------------------
def _drag(page, dx: int) -> None:
    """Orbit the view by dragging across the 3D area."""
    x, y = VIEWPORT["width"] // 4, VIEWPORT["height"] // 2
    page.mouse.move(x, y)
    page.mouse.down()
    for i in range(1, 11):
        page.mouse.move(x + dx * i / 10, y)
    page.mouse.up()


def test_keyframes_added_on_the_page_make_a_camera_path_that_renders(trained_run, tmp_path: Path) -> None:
    sync_api, chromium = require_browser()
    _, run_dir = trained_run
    cfg = ViewerConfig(load_config=run_dir / "config.json", port=0, host="127.0.0.1", preview_side=64, final_side=96)
    handle = serve(cfg)
    panel = handle.view.camera_paths
    try:
        with sync_api.sync_playwright() as playwright:
            browser, page = _open(playwright, chromium, handle.url)
            try:
                _wait(lambda: handle.view.client_count > 0, 60, "the page to connect")
                for n in range(1, 4):
                    if n > 1:
                        _drag(page, 120)
                    page.get_by_role("button", name="Add keyframe").click()
                    _wait(lambda n=n: len(panel.keyframes) == n, 30, f"keyframe {n}")
                page.get_by_role("button", name="Render").click()
                _wait(lambda: bool(panel.saved), 30, "the camera path to be saved")
                _wait(lambda: "fourierf-render camera-path" in page.inner_text("body"), 30, "the command on the page")
            finally:
                browser.close()
    finally:
        handle.stop()
    saved = sorted((run_dir / "camera_paths").glob("*.json"))
    assert saved
    content = json.loads(saved[-1].read_text())
    assert len(content["keyframes"]) == 3
    centres = np.array([np.reshape(k["matrix"], (4, 4))[:3, 3] for k in content["keyframes"]])
    assert np.linalg.norm(np.diff(centres, axis=0), axis=1).min() > 1e-3, "the drags did not move the view"
    out = tmp_path / "path"
    args = ["--load-config", str(run_dir / "config.json"), "--camera-path-filename", str(saved[-1])]
    args += ["--output-dir", str(out), "--outputs", "rgb", "--resolution-scale", "0.25"]
    result = render_main(["camera-path", *args])
    assert len(result.frames["rgb"]) == len(content["camera_path"]) and (out / "rgb.gif").exists()
