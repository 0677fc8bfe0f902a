"""The page's features without a browser: the final picture coarse to full with its progress, the default final
size, the status and its hint, the depth legend, errors in the page's words, the camera-path editor and the
checkpoint timeline (a fake browser stands in for viser's client)."""

from __future__ import annotations

import contextlib
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest

from fourierf_plugin.cameras.camera_path import read_camera_path
from fourierf_plugin.viewer import server as server_module
from fourierf_plugin.viewer.page_text import depth_legend, for_the_page, status_text
from fourierf_plugin.viewer.render_service import Rendered
from fourierf_plugin.viewer.server import ViewerServer, ViewerSettings, open_server, stage_sizes
from fourierf_plugin.viewer.viewed_run import TrainingProgress, ViewedRun
from tests.conftest import require_module
from tests.helpers import FakeClock, train_tiny
from tests.viewer.fake_client import FakeClient

VISER_WHY = "the viewer needs viser (pip install '.[viewer]')"


# -- pure -----------------------------------------------------------------------------------------------------------
def test_the_final_picture_is_drawn_coarse_to_full_from_above_the_preview_size() -> None:
    assert stage_sizes(768, 512, (0.25, 0.5, 1.0), 128) == [(192, 128), (384, 256), (768, 512)]
    assert stage_sizes(768, 512, (0.25, 0.5, 1.0), 256) == [(384, 256), (768, 512)]  # 192 px adds nothing
    assert stage_sizes(100, 100, (0.25, 0.5, 1.0), 100) == [(100, 100)]


def test_the_status_says_how_the_run_stands_and_hints_at_a_zero_cutoff() -> None:
    progress = TrainingProgress(120, 300, {"loss": 0.0123, "psnr": 19.5}, 0.42, 0.5)
    live = status_text(100, (0.4, 0.5), progress, (0.42, 0.5), 0.05)
    assert "training** step 120 / 300" in live and "density 0.42" in live and "psnr 19.5" in live
    assert "nearly blank" not in live
    progress.finished, progress.step = True, 300
    assert "finished at step 300" in status_text(300, (1, 1), progress, (1.0, 1.0), None)
    progress.interrupted = True
    assert "stopped (interrupted) at step 300" in status_text(300, (1, 1), progress, (1.0, 1.0), None)
    assert "nearly blank" in status_text(300, (1, 1), None, (0.0, 1.0), None)


def test_the_depth_legend_names_its_range_and_errors_name_no_flags() -> None:
    assert "2.5" in depth_legend(2.5, 6.0) and "6" in depth_legend(2.5, 6.0)
    page = for_the_page("--frequency-cap 2 is outside [0, 1]; try --level 0.5 or --mystery 3")
    assert "--" not in page and "the density cutoff" in page and "the surface level" in page


# -- a page on a trained run ------------------------------------------------------------------------------------------
class StubRenders:
    """``render_view`` answering at once with a picture of the asked size, reporting progress halfway."""

    def __init__(self, page_ref: list) -> None:
        self.sizes: list[tuple[int, int]] = []
        self.progress_seen: list[str] = []
        self.page_ref = page_ref

    def __call__(self, model, camera, cutoffs, abort=None, quality=None, render_size=None, progress=None):
        size = render_size or (camera.width, camera.height)
        self.sizes.append(size)
        if progress is not None:
            progress(0.5)
            page = self.page_ref[0]
            self.progress_seen.append(page.progress_text.content if page.progress_text.visible else "")
        blank = np.full((camera.height, camera.width, 3), len(self.sizes), dtype=np.uint8)
        return Rendered(blank, blank, blank, 0.01, depth_range=(2.0, 4.0))


@contextlib.contextmanager
def _page(run, monkeypatch, settings: ViewerSettings) -> Iterator[tuple[ViewerServer, StubRenders, FakeClock]]:
    require_module("viser", VISER_WHY)
    trainer, run_dir = run
    holder: list = []
    renders = StubRenders(holder)
    monkeypatch.setattr(server_module, "render_view", renders)
    clock = FakeClock()
    pipeline = trainer.pipeline
    viewed = ViewedRun(pipeline.model, pipeline.model.max_iters, run_dir)
    view = ViewerServer(
        open_server(0, "127.0.0.1"), viewed, pipeline.datamanager.reference_outputs, None, settings,
        clock=clock, render_thread=False,
    )  # fmt: skip
    holder.append(view)
    try:
        yield view, renders, clock
    finally:
        view.stop()


def test_the_final_picture_comes_in_stages_with_its_progress_on_the_page(trained_run, monkeypatch) -> None:
    with _page(trained_run, monkeypatch, ViewerSettings(preview_side=64, final_side=256)) as (view, renders, clock):
        client = FakeClient()
        view.connect(client)
        assert view.do_due_work()  # the preview
        clock.now += 1.0
        assert view.do_due_work()  # the final picture, coarse to full
        assert renders.sizes[1:] == [(128, 128), (256, 256)]
        assert [image.shape[0] for image in client.scene.images] == [64, 256, 256]  # each stage shown at full size
        assert renders.progress_seen == ["final picture: stage 1 / 2 (128 px), 50 %",
                                         "final picture: stage 2 / 2 (256 px), 50 %"]  # fmt: skip
        assert not view.progress_text.visible and view.final_renders == 1  # done: the progress hidden
        view.output.value = "depth"
        assert view.do_due_work()
        assert view.legend.visible and "2" in view.legend.content and "4" in view.legend.content


def test_the_final_size_defaults_to_the_training_images(trained_run, monkeypatch) -> None:
    with _page(trained_run, monkeypatch, ViewerSettings()) as (view, _, _):
        assert view.settings.final_side == 100 and view.settings.preview_side == 100  # the tiny scene's 100x100


def test_keyframes_from_the_view_make_a_camera_path_saved_under_a_fresh_name(trained_run, monkeypatch) -> None:
    with _page(trained_run, monkeypatch, ViewerSettings(preview_side=32, final_side=64)) as (view, _, _):
        panel = view.camera_paths
        client = FakeClient()
        view.connect(client)
        cameras = trained_run[0].pipeline.datamanager.reference_outputs.cameras
        assert panel.save(client) is None and "two keyframes" in client.notifications[-1][1]
        for index in range(3):
            client.camera.move_to(cameras, index)
            assert panel.add(client)
        assert not panel.render_button.disabled
        assert panel.show_preview(1.0, client)  # the view moves to the path's end: the last keyframe
        np.testing.assert_allclose(client.camera.position, cameras.camera_to_worlds[2, :, 3].numpy(), atol=1e-4)
        assert not panel.show_preview(float("nan"), client) and not panel.show_preview("x", client)
        panel.seconds.value, panel.fps.value = 1.0, 10.0
        folder = view.viewed.run_dir / "camera_paths"
        before = {p: p.read_bytes() for p in folder.glob("*.json")} if folder.is_dir() else {}
        first, second = panel.save(client), panel.save(client)
        assert first is not None and second is not None and "fourierf-render camera-path --load-config" in first
        written = [Path(command.split("--camera-path-filename ")[1]) for command in (first, second)]
        assert written[0] != written[1] and not set(written) & set(before), "a path was written over another"
        assert all(p.read_bytes() == content for p, content in before.items())
        path = read_camera_path(written[0])
        assert len(path.cameras) == 10 and path.fps == 10.0 and (path.width, path.height) == (100, 100)
        np.testing.assert_allclose(path.cameras.camera_to_worlds[0].numpy(),
                                   cameras.camera_to_worlds[0].numpy(), atol=1e-4)  # fmt: skip
        assert second in view.camera_paths.info.content


@pytest.fixture(scope="module")
def run_with_checkpoints(tmp_path_factory):
    """A tiny run that kept three checkpoints along its ramp and wrote a mesh at step 20."""
    extra = ["--steps-per-save", "10", "--keep-checkpoints", "3", "--export-mesh-at", "20",
             "--pipeline.model.fourier.ramp-fraction", "1.0"]  # fmt: skip
    return train_tiny(tmp_path_factory.mktemp("timeline"), iters=30, extra=extra)


def test_the_timeline_scrubs_through_the_checkpoints_and_lists_the_meshes(run_with_checkpoints, monkeypatch) -> None:
    with _page(run_with_checkpoints, monkeypatch, ViewerSettings(preview_side=32, final_side=64)) as (view, _, _):
        timeline = view.timeline
        assert timeline is not None and timeline.steps == [10, 20, 30]
        assert "step-000020.ply (step 20)" in timeline.text.content
        top = view.density_slider.max
        assert timeline.load(0)
        assert view.viewed.step == 10 and view.density_slider.max < top  # the curriculum's cutoff at step 10
        assert "**step 10:" in timeline.text.content
        state = {k: v.clone() for k, v in view.viewed.model.state_dict().items()}
        assert timeline.load(2) and view.viewed.step == 30
        assert any(not (state[k].shape == v.shape and bool((state[k] == v).all()))
                   for k, v in view.viewed.model.state_dict().items())  # fmt: skip
        assert not timeline.load(7) and not timeline.load(True) and not timeline.load("1")
