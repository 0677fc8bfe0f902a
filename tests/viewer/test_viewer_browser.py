"""The viewer in a real headless browser: the page loads, the render is drawn, and a cutoff of 0 makes it smoother.

Debian's chromium driven by playwright (no browser download). Outside CI the test skips when playwright, viser or
chromium is missing; in CI (which installs them) it fails instead.
"""

from __future__ import annotations

import io
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

from fourierf_plugin.scripts.viewer import ViewerConfig, ViewerHandle, serve
from fourierf_plugin.viewer.headless import CHROMIUM, CHROMIUM_ARGS
from fourierf_plugin.viewer.render_service import high_frequency_energy
from tests.conftest import require_module, skip_outside_ci

pytestmark = pytest.mark.slow

VIEWPORT = {"width": 960, "height": 640}


def require_chromium() -> Path:
    if not CHROMIUM.exists():
        skip_outside_ci(f"{CHROMIUM} is absent: install Debian's chromium package to run the browser test")
    return CHROMIUM


def _wait(condition: Callable[[], bool], seconds: float, what: str) -> None:
    deadline = time.monotonic() + seconds
    while not condition():
        if time.monotonic() > deadline:
            pytest.fail(f"timed out after {seconds:.0f} s waiting for {what}")
        time.sleep(0.1)


def _final_render_count(handle: ViewerHandle) -> int:
    """How many final-size pictures the viewer has sent (the preview comes first, then the final one)."""
    return handle.view.final_renders


def render_area(screenshot: bytes) -> np.ndarray:
    """The middle of the 3D view (left of the control panel), where the background render shows, as RGB."""
    image = np.asarray(Image.open(io.BytesIO(screenshot)).convert("RGB"), dtype=np.float64)
    height, width = image.shape[:2]
    return image[height // 4 : 3 * height // 4, width // 8 : width // 2]


def settled_screenshot(page, handle: ViewerHandle, renders_before: int) -> np.ndarray:
    """A screenshot once a new final picture has been sent and had time to reach the page."""
    _wait(lambda: _final_render_count(handle) > renders_before, 40, "the final render")
    time.sleep(1.5)
    return render_area(page.screenshot())


def test_the_page_shows_the_render_and_a_zero_cutoff_smooths_it(trained_run) -> None:
    require_module("viser", "the viewer needs viser (pip install '.[viewer]')")
    sync_api = require_module("playwright.sync_api", "the browser test needs playwright (pip install playwright)")
    chromium = require_chromium()
    _, run_dir = trained_run
    cfg = ViewerConfig(load_config=run_dir / "config.json", port=0, host="127.0.0.1", preview_side=64, final_side=256)
    handle = serve(cfg)
    try:
        with sync_api.sync_playwright() as playwright:
            browser = playwright.chromium.launch(executable_path=str(chromium), args=list(CHROMIUM_ARGS))
            try:
                page = browser.new_page(viewport=VIEWPORT)
                page.goto(handle.url, wait_until="load", timeout=30_000)
                _wait(lambda: handle.view.client_count > 0, 40, "the page to connect")  # a cold chromium start
                full = settled_screenshot(page, handle, 0)
                assert full.var() > 100.0, f"the render area is flat (variance {full.var():.1f}): nothing was drawn"

                before = _final_render_count(handle)
                handle.view.density_slider.value = 0.0
                handle.view.color_slider.value = 0.0
                coarse = settled_screenshot(page, handle, before)
            finally:
                browser.close()
    finally:
        handle.stop()
    assert not np.array_equal(full, coarse)
    energies = high_frequency_energy(coarse), high_frequency_energy(full)
    assert energies[0] < 0.8 * energies[1], f"high-frequency energy at cutoff 0 vs 1: {energies}"
