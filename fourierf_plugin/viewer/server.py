"""The web page: a viser server whose background is the model's render at each browser's camera, and its controls.

Controls: which picture (rgb, depth with its legend, accumulation), the density and colour cutoffs (0 up to the run's
own value at its step), the preview and final sizes, "mesh at this cutoff", the camera-path editor
(``viewer.camera_path_panel``) and, on a saved run, the checkpoint timeline (``viewer.timeline``). One background
thread renders for every connected browser: a small preview while the camera (or a slider) moves, then the final
size once it has rested ``rest_seconds``, coarse to full with its progress on the page. viser's own callbacks only
record what changed, so the page never waits for the model.

Without its own thread (``render_thread=False``) the page does nothing until its host calls :meth:`do_due_work`: the
live viewer calls it from the training thread between steps (why: ``viewer.live``), every picture sized to cost
``picture_seconds``; when the run ends, :meth:`become_saved_run` starts the thread and the page carries on as a
saved run's.
"""

from __future__ import annotations

import collections
import contextlib
import dataclasses
import importlib
import ipaddress
import math
import os
import socket
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from types import ModuleType
from typing import TYPE_CHECKING

import numpy as np
import torch

from fourierf_plugin.exporter.marching_cubes import describe, export_field_mesh
from fourierf_plugin.utils.console import get_console, warn
from fourierf_plugin.utils.errors import UserError, fail
from fourierf_plugin.viewer.camera_path_panel import CameraPathPanel
from fourierf_plugin.viewer.page_text import depth_legend, final_progress, for_the_page, status_text
from fourierf_plugin.viewer.render_budget import PreviewPacer, RenderBudget
from fourierf_plugin.viewer.render_service import (
    OUTPUTS,
    Output,
    PreviewQuality,
    Rendered,
    ViewCamera,
    camera_from_opencv_pose,
    render_view,
)
from fourierf_plugin.viewer.scene_view import add_test_views, build_scene
from fourierf_plugin.viewer.timeline import Timeline
from fourierf_plugin.viewer.viewed_run import ViewedRun

if TYPE_CHECKING:
    import viser

    from fourierf_plugin.data.dataparser_base import DataparserOutputs

EXTRA_FIX = "pip install 'fourierf[viewer]'"
MESH_RESOLUTION = 128
LOOPBACK = "127.0.0.1"
PREVIEW_SIDES = (32, 512)
FINAL_SIDES = (64, 2048)
MESH_EVERY_SECONDS = 10.0
"""The least time between two meshes asked for from the page (each costs seconds and megabytes)."""
MESH_FILES_PER_RUN = 50
MESH_BYTES_PER_RUN = 512 * 2**20
"""How many viewer meshes, and how many bytes of them, one run's ``meshes/`` may hold before the button refuses."""


def require_viser() -> ModuleType:
    """The viser module, or one clear error naming the extra that provides it."""
    try:
        return importlib.import_module("viser")
    except ImportError as err:
        problem = f"the web viewer needs the optional package viser, which is not installed ({err})"
        raise UserError(problem, EXTRA_FIX) from err


def is_loopback(host: str) -> bool:
    """Whether ``host`` is reachable from this machine only (``localhost``, 127.0.0.0/8, ``::1``)."""
    if host == "localhost":
        return True
    try:
        return ipaddress.ip_address(host.strip("[]")).is_loopback
    except ValueError:
        return False


def check_host(host: str, flag: str = "--host") -> None:
    """A host the server can bind: an address of this machine or a name that resolves (one clear error otherwise)."""
    try:
        socket.getaddrinfo(host, None)
    except (OSError, UnicodeError) as err:
        fail(f"{flag} {host!r} is not an address of this machine ({err})", f"use {flag} {LOOPBACK} (this machine only)")


def same_origin_request(host: str) -> Callable[[object, object], object]:
    """A websocket handshake check: a browser's ``Origin`` must be the page's own (``Host``), so a page of another
    site open in the same browser cannot drive the viewer; on a loopback bind the ``Host`` must be a loopback name
    too (a rebound DNS name reaches 127.0.0.1 only through a foreign ``Host``). Clients without ``Origin`` (no
    browser, so no foreign page) pass."""
    from urllib.parse import urlsplit

    def refused(request) -> str | None:
        headers = request.headers
        if headers.get("Upgrade", "").lower() != "websocket":
            return None
        served = headers.get("Host", "")
        served_name = urlsplit(f"//{served}").hostname or ""
        if is_loopback(host) and not is_loopback(served_name):
            return f"host {served!r} is not this machine"
        origin = headers.get("Origin")
        if origin is not None and urlsplit(origin).netloc != served:
            return f"origin {origin!r} is not the viewer's page"
        return None

    def check(connection, request):
        reason = refused(request)
        if reason is not None:
            return connection.respond(403, f"refused: {reason}\n")
        return None

    return check


_SERVE_LOCK = threading.Lock()


@contextlib.contextmanager
def _checked_handshakes(host: str):
    """While viser opens its server: every websocket handshake passes ``same_origin_request`` before viser's own
    request handler (viser has no option for it)."""
    import websockets.asyncio.server as ws_server

    original = ws_server.serve
    check = same_origin_request(host)

    def serve(*args, **kwargs):
        inner = kwargs.get("process_request")

        def process_request(connection, request):
            response = check(connection, request)
            if response is not None or inner is None:
                return response
            return inner(connection, request)

        kwargs["process_request"] = process_request
        return original(*args, **kwargs)

    with _SERVE_LOCK:
        ws_server.serve = serve  # type: ignore[assignment]
        try:
            yield
        finally:
            ws_server.serve = original  # type: ignore[assignment]


def served_url(host: str, port: int) -> str:
    """The address a browser on this machine opens: the bound host itself, ``localhost`` for every interface."""
    shown = "localhost" if host in ("0.0.0.0", "::", "") else host
    return f"http://[{shown}]:{port}" if ":" in shown else f"http://{shown}:{port}"


def open_server(port: int, host: str = LOOPBACK) -> viser.ViserServer:
    """A viser server on ``host``:``port``, or on the next free port when it is taken (said aloud, with the address);
    port 0 takes any free port. A host other machines can reach is warned about: the page has no password."""
    if not 0 <= port <= 65535:
        fail(f"--port {port} is not a TCP port", "pass a port in 1-65535, e.g. 7007 (0: any free port)")
    check_host(host)
    viser_module = require_viser()
    with _checked_handshakes(host):
        server = viser_module.ViserServer(host=host, port=port, verbose=False)
    actual = server.get_port()
    console = get_console()
    if port != 0 and actual != port:
        console.print(f"[yellow]port {port} is in use: the viewer takes the next free port, {actual}[/yellow]")
    console.print(f"[bold]viewer[/bold] at {served_url(host, actual)} (Ctrl-C stops it)")
    if not is_loopback(host):
        warn(
            f"the viewer listens on {host}: other machines that reach this one can open it, without a password, "
            f"and write meshes into the run; for this machine only use --host {LOOPBACK} (an SSH tunnel reaches it "
            "from elsewhere)"
        )
    return server


@dataclass
class ViewerSettings:
    preview_side: int = 256
    """Pixels along the preview's longer side (shown while the camera moves)."""
    final_side: int | None = None
    """Pixels along the final picture's longer side (shown once the camera rests); None: the training images'."""
    final_stages: tuple[float, ...] = (0.25, 0.5, 1.0)
    """The final picture is drawn coarse to full at these shares of its side (those larger than the preview)."""
    picture_seconds: float | None = None
    """What every picture may cost (live training: the budget's share of the time between two pictures); each
    renders the pixels that fit and is scaled up. None: previews are paced by ``preview_seconds``, finals full."""
    rest_seconds: float = 0.3
    """How long the camera must stay still before the final picture is rendered."""
    jpeg_quality: int = 90
    preview_seconds: float = 0.25
    """What a preview's render should take: it renders as many of its pixels as fit (at least a quarter of each
    side, learnt from the previews before it) and is scaled up to the preview size."""
    preview_quality: PreviewQuality | None = field(default_factory=PreviewQuality)
    """The cheaper marching of previews (None: previews march as the final picture does)."""
    final_quality: PreviewQuality | None = None
    """The marching of the final picture (None: the model's own, as ``fourierf-render`` draws it)."""
    render_threads: int | None = None
    """Torch threads of the render thread (None: torch's default, every core)."""


@dataclass(frozen=True)
class RenderRecord:
    """One picture sent to a browser (kept for the latency benchmark and the tests)."""

    sent_at: float
    """``time.perf_counter()`` when the picture was handed to the browser's connection."""
    final: bool
    width: int
    height: int
    render_seconds: float
    render_width: int = 0
    """Pixels the model rendered across (a preview may render fewer and be scaled up to ``width``)."""
    render_height: int = 0


@dataclass
class _ClientView:
    """One browser: its camera's generation (bumped on every move) and what is on its screen."""

    client: viser.ClientHandle
    camera_generation: int = 0
    moved_at: float = 0.0
    shown: tuple[int, int] | None = None
    shown_final: bool = False
    pose: tuple[float, ...] = ()
    """The camera as last reported (``camera_state``)."""


def camera_state(camera: viser.CameraHandle) -> tuple[float, ...]:
    """What of a browser's camera changes its picture: orientation, position, field of view and aspect.

    A browser reports its camera again, unchanged, some 50-200 ms after each move; counted as a move, that echo
    abandoned the preview under way and doubled the time from a move to its preview (0.5 s instead of 0.25 s)."""
    pose = np.concatenate([np.asarray(camera.wxyz, dtype=float), np.asarray(camera.position, dtype=float)])
    return (*(float(v) for v in pose), float(camera.fov), float(camera.aspect))


def unique_mesh_path(meshes: Path, f_density: float) -> Path:
    """``meshes/viewer-f<value>.ply``, with -2, -3, ... appended rather than overwriting an earlier export (or
    writing through a link of that name)."""
    stem = f"viewer-f{f_density:.3f}"
    path = meshes / f"{stem}.ply"
    n = 2
    while os.path.lexists(path):
        path = meshes / f"{stem}-{n}.ply"
        n += 1
    return path


def mesh_refusal(run_dir: Path, last_at: float | None, now: float) -> str | None:
    """Why the page may not write another mesh now (None: it may): too soon after the last one, a ``meshes`` folder
    that leads out of the run (a link), or the run's viewer meshes at their count or size limit."""
    if last_at is not None and now - last_at < MESH_EVERY_SECONDS:
        return f"one mesh per {MESH_EVERY_SECONDS:.0f} s: wait {MESH_EVERY_SECONDS - (now - last_at):.0f} s"
    meshes = run_dir / "meshes"
    run_real = os.path.realpath(run_dir)
    if meshes.is_symlink() or os.path.commonpath([run_real, os.path.realpath(meshes)]) != run_real:
        return f"{meshes} is a link out of the run folder: the viewer writes meshes only inside the run"
    if not meshes.is_dir():
        return None
    written = [p for p in meshes.glob("viewer-f*.ply") if not p.is_symlink()]
    total = sum(p.stat().st_size for p in written)
    if len(written) >= MESH_FILES_PER_RUN or total >= MESH_BYTES_PER_RUN:
        return (
            f"{meshes} holds {len(written)} viewer meshes ({total / 2**20:.0f} MiB), the most one run keeps: "
            "remove some to make more"
        )
    return None


def with_final_side(settings: ViewerSettings, train: DataparserOutputs) -> ViewerSettings:
    """``settings`` with a final size: the one given, else the training images' longer side (within the slider's
    range); a preview never larger than it."""
    final = settings.final_side
    if final is None:
        low, high = FINAL_SIDES
        final = min(high, max(low, train.cameras.width, train.cameras.height))
    return dataclasses.replace(settings, final_side=final, preview_side=min(settings.preview_side, final))


def stage_sizes(width: int, height: int, stages: tuple[float, ...], preview_side: int) -> list[tuple[int, int]]:
    """(width, height) of the final picture's coarse-to-full stages: each share of ``stages`` whose longer side is
    larger than the preview's (a coarser one shows nothing the preview did not), then the full size."""
    sizes = []
    for share in sorted(s for s in stages if 0 < s < 1):
        size = (max(1, round(width * share)), max(1, round(height * share)))
        if max(size) > preview_side and size not in sizes:
            sizes.append(size)
    return [*sizes, (width, height)]


class ViewerServer:
    """The page's content and its render thread, on a running viser server (``open_server``)."""

    def __init__(
        self,
        server: viser.ViserServer,
        viewed: ViewedRun,
        train: DataparserOutputs,
        test: DataparserOutputs | None,
        settings: ViewerSettings | None = None,
        budget: RenderBudget | None = None,
        clock: Callable[[], float] = time.perf_counter,
        render_thread: bool = True,
    ) -> None:
        """``render_thread=False``: no thread of its own; pictures and meshes are made only in :meth:`do_due_work`."""
        self.server = server
        self.viewed = viewed
        self.settings = with_final_side(settings or ViewerSettings(), train)
        self.budget = budget or RenderBudget(None)
        self.pacer = PreviewPacer(self.settings.preview_seconds)
        self.live_pacer: PreviewPacer | None = None
        if self.settings.picture_seconds is not None:
            self.live_pacer = PreviewPacer(self.settings.picture_seconds, min_scale=0.1, first_scale=0.25)
        self.train_size = (train.cameras.width, train.cameras.height)
        self.clock = clock
        self._clients: dict[int, _ClientView] = {}
        self._lock = threading.Lock()
        self._wake = threading.Event()
        self._stop = threading.Event()
        self._generation = 0  # bumped by every control change and every new snapshot
        self._changed_at = 0.0
        self.last_render_seconds: float | None = None
        self.renders = 0
        self._rendering = False
        self.final_renders = 0
        self._mesh_requests: collections.deque[viser.ClientHandle | None] = collections.deque()
        self._last_mesh_at: float | None = None
        self._accepted: dict[str, object] = {}
        """The last value of each control that passed ``_valid``: what renders and meshes use."""
        self.log: collections.deque[RenderRecord] = collections.deque(maxlen=1000)
        self.layout, self.frustums = build_scene(server, train, test)
        self._build_gui()
        self.camera_paths = CameraPathPanel(self)
        self.timeline: Timeline | None = None if viewed.live else Timeline(self)
        server.on_client_connect(self.connect)
        server.on_client_disconnect(self._disconnected)
        self._thread: threading.Thread | None = None
        if render_thread:
            self._thread = threading.Thread(target=self._render_loop, name="fourierf-viewer-render", daemon=True)
            self._thread.start()

    def show_test_views(self, test: DataparserOutputs | None) -> None:
        """Add the held-out views' frustums later (the live viewer loads them off the training thread)."""
        if test is not None:
            added = add_test_views(self.server, test, self.layout)
            for frustum in added:
                frustum.visible = self.show_cameras.value
            self.frustums += added

    # -- controls ---------------------------------------------------------------------------------------------------
    def _build_gui(self) -> None:
        gui = self.server.gui
        f_density, f_color = self.viewed.run_cutoffs()
        self.status = gui.add_markdown(self._status_text())
        self.progress_text = gui.add_markdown("", visible=False)
        self.progress_bar = gui.add_progress_bar(0.0, visible=False)
        self.output = gui.add_dropdown("Output", OUTPUTS, initial_value="rgb")
        self.legend = gui.add_markdown("", visible=False)
        self.density_slider = gui.add_slider(
            "Density cutoff", 0.0, max(f_density, 0.01), 0.01, f_density, hint="share of the spectrum kept (0-1)"
        )
        self.color_slider = gui.add_slider(
            "Colour cutoff", 0.0, max(f_color, 0.01), 0.01, f_color, hint="share of the spectrum kept (0-1)"
        )
        self.preview_slider = gui.add_slider("Preview size", *PREVIEW_SIDES, 1, self.settings.preview_side)
        self.final_slider = gui.add_slider("Final size", *FINAL_SIDES, 1, self.settings.final_side)
        self.show_cameras = gui.add_checkbox("Show cameras", True, hint="training views orange, test views blue")
        self.show_cameras.on_update(lambda _: self._show_cameras(self.show_cameras.value))
        self.mesh_button = gui.add_button("Mesh at this cutoff", hint="marching cubes at the density cutoff")
        self._controls = {
            "output": self.output,
            "density": self.density_slider,
            "colour": self.color_slider,
            "preview": self.preview_slider,
            "final": self.final_slider,
        }
        self._accepted = {name: handle.value for name, handle in self._controls.items()}
        for name in self._controls:
            self._controls[name].on_update(lambda _, name=name: self._control_moved(name))
        self.mesh_button.on_click(lambda event: self._mesh_clicked(event.client))

    def _valid(self, name: str, value: object) -> bool:
        """Whether a control's value is one the page offers: a page (or any websocket client) can send anything."""
        if name == "output":
            return isinstance(value, str) and value in OUTPUTS
        if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
            return False
        if name in ("density", "colour"):
            top = max(self.viewed.run_cutoffs()[0 if name == "density" else 1], 0.01)
            return 0.0 <= value <= top + 1e-9
        low, high = PREVIEW_SIDES if name == "preview" else FINAL_SIDES
        return low <= value <= high

    def _control(self, name: str) -> object:
        """A control's value if valid, else its last valid one (the control is set back to it)."""
        handle = self._controls[name]
        value = handle.value
        if self._valid(name, value):
            self._accepted[name] = value
            return value
        with contextlib.suppress(Exception):
            handle.value = self._accepted[name]
        return self._accepted[name]

    def _control_moved(self, name: str) -> None:
        """A page moved a control: redraw for a valid value; an invalid one is set back and changes nothing."""
        before = self._accepted[name]
        if self._control(name) != before:
            self.changed()

    def _mesh_clicked(self, client: viser.ClientHandle | None) -> None:
        """At once on viser's thread, or queued for the host's next :meth:`do_due_work` (no thread of its own)."""
        if self._thread is None:
            self._mesh_requests.append(client)
        else:
            self.export_mesh(client)

    def _show_cameras(self, visible: bool) -> None:
        for frustum in self.frustums:
            frustum.visible = visible

    def changed(self, moving: bool = True) -> None:
        """Everything on screen is out of date (a control moved, or a new snapshot arrived when not ``moving``)."""
        with self._lock:
            self._generation += 1
            if moving:
                self._changed_at = self.clock()
        self._wake.set()

    def follow_run_cutoffs(self) -> None:
        """Widen the sliders to the run's current cutoffs (live training); a slider at its top stays at the top."""
        for slider, value in zip((self.density_slider, self.color_slider), self.viewed.run_cutoffs(), strict=True):
            top = max(value, 0.01)
            at_top = slider.value >= slider.max - 1e-9
            if top != slider.max:
                slider.max = top
                if at_top or slider.value > top:
                    slider.value = top
        for name in ("density", "colour"):
            self._control(name)

    def cutoffs(self) -> tuple[float, float]:
        return float(self._control("density")), float(self._control("colour"))  # type: ignore[arg-type]

    def output_name(self) -> Output:
        return self._control("output")  # type: ignore[return-value]

    def side(self, final: bool) -> int:
        """Pixels along the longer side of a final picture or a preview."""
        return int(self._control("final" if final else "preview"))  # type: ignore[call-overload]

    def refresh_status(self) -> None:
        self.status.content = self._status_text()

    def _status_text(self) -> str:
        viewed = self.viewed
        shown = self.cutoffs() if hasattr(self, "density_slider") else None
        return status_text(viewed.step, viewed.run_cutoffs(), viewed.progress, shown, self.last_render_seconds)

    # -- clients ----------------------------------------------------------------------------------------------------
    def connect(self, client: viser.ClientHandle) -> None:
        """Start drawing for a browser (viser calls this for each one that connects).

        viser registers a browser once its first camera message has arrived, and runs this callback on its thread
        pool, possibly after that message's camera callbacks ran (without ``moved``, not yet registered): so the
        camera counts as reported from here on, not from the next message, which a browser left alone never sends."""
        view = _ClientView(client, camera_generation=1, moved_at=self.clock(), pose=camera_state(client.camera))

        def moved(_: object) -> None:
            pose = camera_state(client.camera)
            with self._lock:
                if pose == view.pose:
                    return  # the browser's echo of the camera it already reported: not a move
                view.pose = pose
                view.camera_generation += 1
                view.moved_at = self.clock()
            self._wake.set()

        client.camera.on_update(moved)
        with self._lock:
            self._clients[client.client_id] = view
        self._wake.set()

    def _disconnected(self, client: viser.ClientHandle) -> None:
        with self._lock:
            self._clients.pop(client.client_id, None)

    @property
    def client_count(self) -> int:
        with self._lock:
            return len(self._clients)

    # -- rendering --------------------------------------------------------------------------------------------------
    def _next_job(self) -> tuple[_ClientView, tuple[int, int], bool] | None:
        """A browser whose picture is out of date, the state to render, and whether at the final size.

        Every camera move is answered by a preview first: the final size only once the camera has rested *and*
        the screen already shows this camera (at some state of the controls). Without the second condition a move
        whose preview was abandoned (the camera moved on during it) went straight to the final picture once the rest
        time had passed during the abandoned render: many times a preview's time, and no preview at all for that
        move."""
        now = self.clock()
        with self._lock:
            for view in self._clients.values():
                if view.camera_generation == 0:
                    continue  # no camera reported yet
                key = (view.camera_generation, self._generation)
                rested = now - max(view.moved_at, self._changed_at) >= self.settings.rest_seconds
                camera_shown = view.shown is not None and view.shown[0] == view.camera_generation
                final = rested and camera_shown
                if key != view.shown or (final and not view.shown_final):
                    return view, key, final
        return None

    def _outdated(self, view: _ClientView, key: tuple[int, int]) -> bool:
        """The browser's camera or a control changed since ``key`` (checked between blocks of a render)."""
        return (view.camera_generation, self._generation) != key or self._stop.is_set()

    def _render_loop(self) -> None:
        if self.settings.render_threads is not None:
            torch.set_num_threads(self.settings.render_threads)  # per thread: training keeps its own count
        while not self._stop.is_set():
            self._export_queued_meshes()
            self._wake.clear()  # before looking: a wake-up set after this is seen by the wait below
            job = self._next_job()
            if job is None:
                self._wake.wait(0.05)  # the timeout: a camera at rest becomes due for its final picture
                continue
            wait = self.budget.wait_seconds()
            if wait > 0:
                self._stop.wait(min(wait, 0.05))
                continue
            if not self._run(job):
                self._stop.wait(1.0)  # a failing render is not retried at full speed

    def _export_queued_meshes(self) -> None:
        """Meshes asked for while the page had no thread of its own (live training)."""
        while self._mesh_requests:
            self.export_mesh(self._mesh_requests.popleft())

    def become_saved_run(self) -> None:
        """The live run has ended: from now on the page works as a saved run's (its own render thread, no budget,
        full-size final pictures, the checkpoint timeline), on the weights it was last given."""
        self.live_pacer = None
        self.budget = RenderBudget(None)
        self.follow_run_cutoffs()
        with contextlib.suppress(Exception):  # the timeline is a convenience: the page works without it
            self.timeline = Timeline(self)
        self.refresh_status()
        self.changed(moving=False)
        if self._thread is None and not self._stop.is_set():
            self._thread = threading.Thread(target=self._render_loop, name="fourierf-viewer-render", daemon=True)
            self._thread.start()

    def _run(self, job: tuple[_ClientView, tuple[int, int], bool]) -> bool:
        """Render one job; False when it failed (said aloud: a failed picture must not end the page or the run)."""
        self._rendering = True
        try:
            self._render(*job)
        except Exception as err:
            warn(f"viewer render failed: {err}")
            return False
        finally:
            self._rendering = False
            self._show_progress(None)
        return True

    @property
    def due(self) -> bool:
        """Work is waiting: a browser's picture is out of date, or a mesh was asked for."""
        return bool(self._mesh_requests) or self._next_job() is not None

    def do_due_work(self) -> bool:
        """On the calling thread: export a requested mesh, else render one due picture if the budget allows; whether
        anything was done. For a page without its own thread (the live viewer's)."""
        if self._stop.is_set():
            return False
        if self._mesh_requests:
            self.export_mesh(self._mesh_requests.popleft())
            return True
        job = self._next_job()
        if job is None or self.budget.wait_seconds() > 0:
            return False
        self._run(job)
        return True

    @property
    def busy(self) -> bool:
        """A picture is being rendered or is due (a browser's view is out of date)."""
        return self._rendering or self._next_job() is not None

    def _sizes(self, pose: ViewCamera, final: bool) -> list[tuple[int, int]]:
        """(width, height) of each picture to render for this job: one paced picture live or for a preview, the
        final picture's coarse-to-full stages otherwise."""
        if self.live_pacer is not None:
            return [self.live_pacer.render_size(pose.width, pose.height)]
        if not final:
            return [self.pacer.render_size(pose.width, pose.height)]
        return stage_sizes(pose.width, pose.height, self.settings.final_stages, self.side(False))

    def _render(self, view: _ClientView, key: tuple[int, int], final: bool) -> None:
        camera = view.client.camera
        pose = camera_from_opencv_pose(camera.wxyz, camera.position, camera.fov, camera.aspect, self.side(final))
        output = self.output_name()
        paced = self.live_pacer is not None or not final
        quality = self.settings.preview_quality if paced else self.settings.final_quality
        sizes = self._sizes(pose, final)
        for stage, size in enumerate(sizes, start=1):
            report = None
            if not paced:
                report = lambda f, stage=stage, size=size: self._show_progress(  # noqa: E731
                    final_progress(stage, len(sizes), max(size), f), f
                )
            started = time.perf_counter()
            with self.viewed.lock:
                rendered = render_view(
                    self.viewed.model,
                    pose,
                    self.cutoffs(),
                    abort=lambda: self._outdated(view, key),
                    quality=quality,
                    render_size=size,
                    progress=report,
                )
            self.budget.charge(started, time.perf_counter() - started)
            if rendered is None:
                return  # the camera or a control moved during the render: the next job is a preview (``_next_job``)
            if paced:
                (self.live_pacer or self.pacer).observe(size[0] * size[1], rendered.seconds)
            self._send(view, key, final and stage == len(sizes), pose, size, rendered, output)

    def _send(
        self,
        view: _ClientView,
        key: tuple[int, int],
        final: bool,
        pose: ViewCamera,
        size: tuple[int, int],
        rendered: Rendered,
        output: Output,
    ) -> None:
        """Put a rendered picture on the browser's screen and record it."""
        view.client.scene.set_background_image(
            rendered.image(output), format="jpeg", jpeg_quality=self.settings.jpeg_quality
        )
        with self._lock:
            view.shown, view.shown_final = key, final
        record = RenderRecord(time.perf_counter(), final, pose.width, pose.height, rendered.seconds, size[0], size[1])
        self.log.append(record)
        self.last_render_seconds = rendered.seconds
        self.renders += 1
        self.final_renders += int(final)
        self.legend.visible = output == "depth"
        if output == "depth":
            self.legend.content = depth_legend(*rendered.depth_range)
        self.refresh_status()

    def _show_progress(self, text: str | None, fraction: float = 0.0) -> None:
        """The final picture's progress under the status (hidden when ``text`` is None)."""
        if not hasattr(self, "progress_bar"):
            return
        if text is None:
            if self.progress_bar.visible:
                self.progress_bar.visible = self.progress_text.visible = False
            return
        self.progress_text.content = text
        self.progress_bar.value = 100.0 * fraction
        self.progress_bar.visible = self.progress_text.visible = True

    # -- mesh -------------------------------------------------------------------------------------------------------
    def export_mesh(self, client: viser.ClientHandle | None = None) -> Path | None:
        """Marching cubes of the density at the slider's cutoff into RUN/meshes/ (never over an earlier file, never
        out of the run, at most one per ``MESH_EVERY_SECONDS`` and ``MESH_FILES_PER_RUN`` per run)."""
        f_density = self.cutoffs()[0]
        refusal = mesh_refusal(self.viewed.run_dir, self._last_mesh_at, self.clock())
        if refusal is not None:
            warn(f"no mesh at cutoff {f_density:.3f}: {refusal}")
            if client is not None:
                client.add_notification("Mesh export", f"no mesh: {refusal}", auto_close_seconds=8.0)
            return None
        self._last_mesh_at = self.clock()
        self.mesh_button.disabled = True
        try:
            with self.viewed.lock:
                path = unique_mesh_path(self.viewed.run_dir / "meshes", f_density)
                report = export_field_mesh(
                    self.viewed.model, self.viewed.step, path, resolution=MESH_RESOLUTION, frequency_cap=f_density
                )
            message = f"mesh at cutoff {f_density:.3f}: {path}"
            get_console().print(message + "; " + "; ".join(describe(report)))
        except UserError as err:
            message, path = f"no mesh at cutoff {f_density:.3f}: {err.problem}", None
            warn(message)
            message = for_the_page(message)
        finally:
            self.mesh_button.disabled = False
        if client is not None:
            client.add_notification("Mesh export", message, auto_close_seconds=8.0)
        return path

    # -- shutdown ---------------------------------------------------------------------------------------------------
    def stop(self) -> None:
        """Stop rendering and close the page's server (idempotent)."""
        if self._stop.is_set():
            return
        self._stop.set()
        self._wake.set()
        if self._thread is not None and self._thread.is_alive() and threading.current_thread() is not self._thread:
            self._thread.join(timeout=30.0)
        self.server.stop()
