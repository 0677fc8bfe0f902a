"""A stand-in for a connected browser (viser's ``ClientHandle``): a camera that can be moved and a screen that
records the pictures sent to it, so the render thread is tested without a browser."""

from __future__ import annotations

import contextlib
import threading
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field

import numpy as np

from fourierf_plugin.cameras.cameras import Cameras
from fourierf_plugin.viewer.render_service import OPENCV_TO_OPENGL, camera_from_dataset
from fourierf_plugin.viewer.scene_view import wxyz_from_rotation


@dataclass
class FakeCamera:
    wxyz: np.ndarray
    position: np.ndarray
    fov: float
    aspect: float = 1.0
    callbacks: list[Callable[[object], None]] = field(default_factory=list)

    def on_update(self, callback: Callable[[object], None]) -> None:
        self.callbacks.append(callback)

    def move_to(self, cameras: Cameras, index: int) -> None:
        """Jump to a dataset camera and tell the viewer, as a browser does after every drag."""
        view = camera_from_dataset(cameras, index)
        self.wxyz = wxyz_from_rotation(view.camera_to_world[:, :3] @ OPENCV_TO_OPENGL)
        self.position = view.camera_to_world[:, 3].copy()
        self.fov, self.aspect = view.fov_y, view.width / view.height
        self.report()

    def report(self) -> None:
        """Send the camera to the viewer (unchanged when called alone: the echo a browser sends after a move)."""
        for callback in self.callbacks:
            callback(self)


@dataclass
class FakeScene:
    images: list[np.ndarray] = field(default_factory=list)
    received: threading.Event = field(default_factory=threading.Event)

    def set_background_image(self, image: np.ndarray, format: str = "auto", jpeg_quality: int | None = None) -> None:
        self.images.append(image.copy())
        self.received.set()


class FakeClient:
    def __init__(self, client_id: int = 1) -> None:
        self.client_id = client_id
        self.camera = FakeCamera(np.array([1.0, 0.0, 0.0, 0.0]), np.zeros(3), 0.7)
        self.scene = FakeScene()
        self.notifications: list[tuple[str, str]] = []

    def add_notification(self, title: str, body: str, **_: object) -> None:
        self.notifications.append((title, body))

    @contextlib.contextmanager
    def atomic(self) -> Iterator[None]:
        yield
