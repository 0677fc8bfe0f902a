"""The page's camera-path editor: keyframes added from the current view, the path drawn in the scene and previewed
by moving the view along it, and a render button that saves it as nerfstudio's camera_path.json in
``RUN/camera_paths/`` (a fresh name, never over a file) and shows the ``fourierf-render camera-path`` command."""

from __future__ import annotations

import math
import shlex
import threading
from typing import TYPE_CHECKING, Protocol

import numpy as np

from fourierf_plugin.cameras.camera_path import Keyframe, camera_path_json, path_frames, write_camera_path
from fourierf_plugin.utils.console import get_console, warn
from fourierf_plugin.viewer.render_service import OPENCV_TO_OPENGL, camera_from_opencv_pose
from fourierf_plugin.viewer.scene_view import wxyz_from_rotation

if TYPE_CHECKING:
    import viser

    from fourierf_plugin.viewer.scene_view import SceneLayout
    from fourierf_plugin.viewer.viewed_run import ViewedRun


class Page(Protocol):
    """What the editor needs of the page (``viewer.server.ViewerServer``)."""

    server: viser.ViserServer
    viewed: ViewedRun
    layout: SceneLayout
    train_size: tuple[int, int]


MAX_KEYFRAMES = 100
SECONDS_RANGE = (0.5, 600.0)
FPS_RANGE = (1.0, 120.0)
PATH_FILES_PER_RUN = 200
"""How many camera paths one run's ``camera_paths/`` may hold before the render button refuses."""
PREVIEW_POINTS = 101
"""Cameras along the path drawn in the scene and visited by the preview slider."""
PATH_COLOR = (20, 180, 60)


def keyframe_of(camera: viser.CameraHandle) -> Keyframe:
    """A browser's current view as a keyframe (OpenGL camera-to-world, vertical fov in degrees, aspect)."""
    view = camera_from_opencv_pose(camera.wxyz, camera.position, camera.fov, camera.aspect, 64)
    return Keyframe(view.camera_to_world.copy(), math.degrees(float(camera.fov)), float(camera.aspect))


def in_range(value: object, low: float, high: float) -> bool:
    """A number the page offers (a page may send anything)."""
    return not isinstance(value, bool) and isinstance(value, (int, float)) and low <= value <= high


class CameraPathPanel:
    """The "Camera path" folder of the page and the keyframes it holds (shared by every browser)."""

    def __init__(self, page: Page) -> None:
        self.page = page
        self.keyframes: list[Keyframe] = []
        self.saved: list[str] = []
        """The commands shown for the paths written so far (the last one on the page)."""
        self._lock = threading.Lock()
        self._drawn: list[object] = []
        gui = page.server.gui
        with gui.add_folder("Camera path"):
            self.add_button = gui.add_button("Add keyframe", hint="the current view becomes the path's next keyframe")
            self.clear_button = gui.add_button("Clear keyframes", disabled=True)
            self.seconds = gui.add_number("Seconds", 4.0, min=SECONDS_RANGE[0], max=SECONDS_RANGE[1], step=0.5)
            self.fps = gui.add_number("Frames per second", 24.0, min=FPS_RANGE[0], max=FPS_RANGE[1], step=1.0)
            self.preview = gui.add_slider(
                "Preview", 0.0, 1.0, 0.01, 0.0, disabled=True, hint="moves your view along the path"
            )
            self.render_button = gui.add_button(
                "Render", disabled=True, hint="saves the path in RUN/camera_paths/ and shows the command to render it"
            )
            self.info = gui.add_markdown("Move the view and press *Add keyframe* (two or more make a path).")
        self.add_button.on_click(lambda event: self.add(event.client))
        self.clear_button.on_click(lambda _: self.clear())
        self.preview.on_update(lambda event: self.show_preview(self.preview.value, event.client))
        self.render_button.on_click(lambda event: self.save(event.client))

    # -- keyframes ---------------------------------------------------------------------------------------------------
    def add(self, client: viser.ClientHandle | None) -> bool:
        if client is None:
            return False
        with self._lock:
            if len(self.keyframes) >= MAX_KEYFRAMES:
                client.add_notification("Camera path", f"a path holds at most {MAX_KEYFRAMES} keyframes")
                return False
            self.keyframes.append(keyframe_of(client.camera))
        self._redraw()
        return True

    def clear(self) -> None:
        with self._lock:
            self.keyframes.clear()
        self._redraw()

    def frames(self, n: int) -> np.ndarray:
        """[n, 3, 4] OpenGL camera-to-worlds along the path."""
        width, height = self.page.train_size
        with self._lock:
            keys = list(self.keyframes)
        return path_frames(keys, n, width, height).camera_to_worlds.double().numpy()

    def _redraw(self) -> None:
        """Keyframe frustums and the path's line in the scene; the controls that need keyframes enabled."""
        scene = self.page.server.scene
        for handle in self._drawn:
            handle.remove()  # type: ignore[attr-defined]
        self._drawn = []
        with self._lock:
            keys = list(self.keyframes)
        scale = self.page.layout.frustum_scale
        for i, key in enumerate(keys):
            self._drawn.append(
                scene.add_camera_frustum(
                    f"/camera path/keyframe {i + 1}",
                    fov=math.radians(key.fov_deg),
                    aspect=key.aspect,
                    scale=scale,
                    color=PATH_COLOR,
                    wxyz=wxyz_from_rotation(key.camera_to_world[:, :3] @ OPENCV_TO_OPENGL),
                    position=key.camera_to_world[:, 3],
                )
            )
        if len(keys) >= 2:
            points = self.frames(PREVIEW_POINTS)[:, :, 3]
            segments = np.stack([points[:-1], points[1:]], axis=1)
            self._drawn.append(
                scene.add_line_segments(
                    "/camera path/line", segments, PATH_COLOR, thickness=2.0, thickness_units="screen"
                )
            )
        self.clear_button.disabled = not keys
        self.preview.disabled = self.render_button.disabled = len(keys) < 2
        self.info.content = (
            f"{len(keys)} keyframe{'s' if len(keys) != 1 else ''}"
            + ("" if len(keys) >= 2 else ": add another to make a path")
            + (f"  \nlast saved: `{self.saved[-1]}`" if self.saved else "")
        )

    def show_preview(self, position: object, client: viser.ClientHandle | None) -> bool:
        """Move the browser's view to ``position`` (0-1) along the path: the page then draws it from there."""
        if client is None or len(self.keyframes) < 2 or not in_range(position, 0.0, 1.0):
            return False
        frames = self.frames(PREVIEW_POINTS)
        c2w = frames[round(float(position) * (PREVIEW_POINTS - 1))]
        with client.atomic():
            client.camera.wxyz = wxyz_from_rotation(c2w[:, :3] @ OPENCV_TO_OPENGL)
            client.camera.position = c2w[:, 3]
        return True

    # -- saving --------------------------------------------------------------------------------------------------------
    def save(self, client: viser.ClientHandle | None = None) -> str | None:
        """Write the path as camera_path.json (a fresh name in RUN/camera_paths/) and return the render command."""
        seconds, fps = self.seconds.value, self.fps.value
        problem = None
        if len(self.keyframes) < 2:
            problem = "add at least two keyframes first"
        elif not in_range(seconds, *SECONDS_RANGE) or not in_range(fps, *FPS_RANGE):
            problem = (
                f"seconds must be within {SECONDS_RANGE[0]:g}-{SECONDS_RANGE[1]:g} and frames per second within "
                f"{FPS_RANGE[0]:g}-{FPS_RANGE[1]:g}"
            )
        folder = self.page.viewed.run_dir / "camera_paths"
        if problem is None and folder.is_dir() and len(list(folder.glob("*.json"))) >= PATH_FILES_PER_RUN:
            problem = f"{folder} holds {PATH_FILES_PER_RUN} camera paths, the most one run keeps: remove some"
        if problem is not None:
            warn(f"no camera path written: {problem}")
            if client is not None:
                client.add_notification("Camera path", f"not saved: {problem}", auto_close_seconds=8.0)
            return None
        width, height = self.page.train_size
        with self._lock:
            keys = list(self.keyframes)
        try:
            path = write_camera_path(folder, camera_path_json(keys, width, height, float(fps), float(seconds)))
        except OSError as err:
            warn(f"no camera path written: {err}")
            if client is not None:
                client.add_notification("Camera path", f"not saved: {err.strerror or err}", auto_close_seconds=8.0)
            return None
        config = self.page.viewed.run_dir / "config.json"
        command = (
            f"fourierf-render camera-path --load-config {shlex.quote(str(config))} "
            f"--camera-path-filename {shlex.quote(str(path))}"
        )
        self.saved.append(command)
        get_console().print(f"camera path saved: {path}\nrender it with: {command}", soft_wrap=True)
        self._redraw()
        if client is not None:
            note = f"{path.name}: render it with {command}"
            client.add_notification("Camera path saved", note, auto_close_seconds=20.0)
        return command
