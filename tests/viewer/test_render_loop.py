"""The viewer's render thread, driven step by step: a stand-in ``render_view`` blocks until the test lets it finish,
and a fake clock decides when the camera has rested, so each test fixes the order of camera moves and renders."""

from __future__ import annotations

import queue
import threading
from collections.abc import Iterator
from dataclasses import dataclass

import numpy as np
import pytest
import torch

from fourierf_plugin.cameras.cameras import Cameras
from fourierf_plugin.viewer import server as server_module
from fourierf_plugin.viewer.render_service import Rendered, ViewCamera
from fourierf_plugin.viewer.server import ViewerServer, ViewerSettings, open_server
from fourierf_plugin.viewer.viewed_run import ViewedRun
from tests.conftest import require_module
from tests.helpers import FakeClock
from tests.viewer.fake_client import FakeClient

GUARD_S = 20.0
"""Only a failing test ever waits this long (for a render the thread should have started)."""


@dataclass
class Call:
    """One render the thread asked for: its size, whether a preview, and the test's hand on when it ends."""

    camera: ViewCamera
    preview: bool
    abort: object
    threads: int
    release: threading.Event


class ScriptedRenders:
    """Replaces ``render_view`` in the server: each call is queued for the test and waits to be released; released,
    it honours ``abort`` as the real one does between blocks."""

    def __init__(self) -> None:
        self.calls: queue.Queue[Call] = queue.Queue()
        self.closed = threading.Event()

    def __call__(self, model, camera, cutoffs, abort=None, quality=None, render_size=None, progress=None):
        if self.closed.is_set():
            return None
        call = Call(camera, quality is not None, abort, torch.get_num_threads(), threading.Event())
        self.calls.put(call)
        if self.closed.is_set():
            call.release.set()
        assert call.release.wait(GUARD_S), "the test never released the render"
        if abort is not None and abort():
            return None
        blank = np.zeros((camera.height, camera.width, 3), dtype=np.uint8)
        return Rendered(blank, blank, blank, 0.01)

    def next(self) -> Call:
        try:
            return self.calls.get(timeout=GUARD_S)
        except queue.Empty:
            pytest.fail("the render thread started no render")

    def none_pending(self) -> bool:
        return self.calls.empty()


@pytest.fixture
def page(trained_run, monkeypatch) -> Iterator[tuple[ViewerServer, ScriptedRenders, FakeClock]]:
    require_module("viser", "the viewer needs viser (pip install '.[viewer]')")
    trainer, run_dir = trained_run
    renders = ScriptedRenders()
    monkeypatch.setattr(server_module, "render_view", renders)
    clock = FakeClock()
    pipeline = trainer.pipeline
    viewed = ViewedRun(pipeline.model, pipeline.model.max_iters, run_dir)
    settings = ViewerSettings(preview_side=64, final_side=128, render_threads=1)
    server = open_server(0, "127.0.0.1")
    view = ViewerServer(server, viewed, pipeline.datamanager.reference_outputs, None, settings, clock=clock)
    try:
        yield view, renders, clock
    finally:
        renders.closed.set()
        for call in list(renders.calls.queue):
            call.release.set()
        view.stop()


def _finish(call: Call, view: ViewerServer) -> None:
    """Let a render end and wait until its picture is on the (fake) screen."""
    client = view._clients[1].client
    client.scene.received.clear()
    call.release.set()
    assert client.scene.received.wait(GUARD_S), "the released render sent no picture"


def _connected_at_rest(page, trained_run) -> tuple[FakeClient, Cameras]:
    """A browser connected and shown its preview and final picture: the page is at rest. The client and the
    dataset cameras to move it to."""
    view, renders, clock = page
    client = FakeClient()
    view.connect(client)
    _finish(renders.next(), view)
    clock.now += 1.0
    _finish(renders.next(), view)
    trainer, _ = trained_run
    return client, trainer.pipeline.datamanager.reference_outputs.cameras


def test_a_browser_is_drawn_from_the_camera_it_connected_with(page) -> None:
    """viser runs the connect callback after the first camera message, whose camera callbacks then missed the
    viewer: before the fix nothing was drawn until the browser happened to report its camera again."""
    view, renders, clock = page
    view.connect(FakeClient())  # no camera message follows
    first = renders.next()
    assert first.preview and max(first.camera.width, first.camera.height) == 64
    _finish(first, view)
    clock.now += 1.0  # the camera has rested
    final = renders.next()
    assert not final.preview and max(final.camera.width, final.camera.height) == 128
    _finish(final, view)


def test_a_move_answered_during_an_abandoned_preview_still_gets_a_preview(page, trained_run) -> None:
    """The dropped preview of the latency benchmark: the camera moves again during a move's preview; the preview
    under way is abandoned, and by then the camera has 'rested' longer than the rest time. The next picture must
    still be a preview (before the fix it was the final one: seconds later, and no preview for the move)."""
    view, renders, clock = page
    client, cameras = _connected_at_rest(page, trained_run)

    client.camera.move_to(cameras, 1)  # the move
    preview = renders.next()
    assert preview.preview
    client.camera.move_to(cameras, 2)  # the next move, during the preview
    clock.now += 1.0  # the preview takes longer than the rest time
    preview.release.set()  # it sees the camera moved and is abandoned
    answer = renders.next()
    assert answer.preview, "the move was answered with the final picture, never with a preview"
    _finish(answer, view)
    clock.now += 1.0
    final = renders.next()
    assert not final.preview
    _finish(final, view)
    assert renders.none_pending()


def test_the_browsers_echo_of_an_unchanged_camera_does_not_abandon_the_preview(page, trained_run) -> None:
    """A browser reports its camera again, unchanged, 50-200 ms after a move. Before the fix that echo counted as a
    move: the preview under way was abandoned and rendered again, doubling the latency benchmark's 0.25 s."""
    view, renders, clock = page
    client, cameras = _connected_at_rest(page, trained_run)

    client.camera.move_to(cameras, 1)
    preview = renders.next()
    client.camera.report()  # the echo, during the preview
    assert not preview.abort(), "the echo of an unchanged camera abandoned the preview"
    _finish(preview, view)
    clock.now += 1.0
    final = renders.next()
    assert not final.preview
    _finish(final, view)
    assert renders.none_pending()


def test_the_render_thread_uses_its_own_thread_count(page) -> None:
    view, renders, _ = page
    before = torch.get_num_threads()
    view.connect(FakeClient())
    call = renders.next()
    assert call.threads == 1  # ViewerSettings.render_threads
    _finish(call, view)
    assert torch.get_num_threads() == before  # this thread's count is untouched


def test_a_page_without_its_own_thread_works_only_when_its_host_asks(trained_run, monkeypatch, tmp_path) -> None:
    """The live viewer's page: no render thread; each ``do_due_work`` makes at most one picture (or one requested
    mesh) on the calling thread, so the training thread that calls it between steps is the only one computing."""
    require_module("viser", "the viewer needs viser (pip install '.[viewer]')")
    trainer, run_dir = trained_run
    threads: list[threading.Thread] = []

    def render_here(model, camera, cutoffs, abort=None, quality=None, render_size=None, progress=None):
        threads.append(threading.current_thread())
        blank = np.zeros((camera.height, camera.width, 3), dtype=np.uint8)
        return Rendered(blank, blank, blank, 0.01)

    meshes: list[object] = []
    monkeypatch.setattr(server_module, "render_view", render_here)
    monkeypatch.setattr(ViewerServer, "export_mesh", lambda self, client=None: meshes.append(client))
    clock = FakeClock()
    pipeline = trainer.pipeline
    viewed = ViewedRun(pipeline.model, pipeline.model.max_iters, run_dir)
    settings = ViewerSettings(preview_side=64, final_side=128)
    server = open_server(0, "127.0.0.1")
    view = ViewerServer(
        server, viewed, pipeline.datamanager.reference_outputs, None, settings, clock=clock, render_thread=False
    )
    try:
        client = FakeClient()
        view.connect(client)
        assert view.due and not client.scene.images  # due, but nothing drawn until asked
        assert view.do_due_work() and threads == [threading.current_thread()]
        assert len(client.scene.images) == 1 and client.scene.images[0].shape[0] == 64  # the preview first
        assert not view.due and not view.do_due_work()  # at rest, nothing more until the rest time has passed
        clock.now += 1.0
        assert view.do_due_work() and client.scene.images[-1].shape[0] == 128  # then the final picture
        view._mesh_clicked(client)  # the button, as viser calls it: queued, not run on viser's thread
        assert not meshes and view.due
        assert view.do_due_work() and meshes == [client]
        assert not view.due
    finally:
        view.stop()
