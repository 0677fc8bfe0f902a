"""The 3D scene around the render: the cameras a run was trained on (with their images) and the held-out ones.

The few-shot training views are the whole story of a FourieRF run, so they are drawn bright with their pictures; the
test views are drawn apart, thin and blue, without pictures. The world's up direction is the training cameras' mean
up vector (z for Blender scenes, y for LLFF ones), and a new browser starts at the first training view.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from fourierf_plugin.cameras.cameras import Cameras
from fourierf_plugin.utils.colormaps import to_uint8
from fourierf_plugin.utils.errors import UserError
from fourierf_plugin.viewer.render_service import OPENCV_TO_OPENGL, camera_from_dataset

if TYPE_CHECKING:
    import viser

    from fourierf_plugin.data.dataparser_base import DataParser, DataparserOutputs

TRAIN_COLOR = (255, 140, 0)
TEST_COLOR = (70, 130, 255)
FRUSTUM_IMAGE_SIDE = 96
"""Pixels along the long side of a frustum's picture: enough to recognise the view, small enough to send quickly."""


@dataclass(frozen=True)
class SceneLayout:
    """Where things are: the world up, a point to look at, and a frustum size in scene units."""

    up: np.ndarray
    target: np.ndarray
    frustum_scale: float


def scene_layout(cameras: Cameras) -> SceneLayout:
    """Up = the cameras' mean up vector; target = the point nearest to all their viewing axes (the object a turntable
    capture circles, or the middle of a forward-facing scene); frustums a twentieth of the cameras' distance to it."""
    c2w = cameras.camera_to_worlds.detach().cpu().double().numpy()
    up = c2w[:, :, 1].mean(axis=0)
    up = up / np.linalg.norm(up) if np.linalg.norm(up) > 1e-6 else np.array([0.0, 0.0, 1.0])
    target = nearest_point_to_axes(c2w[:, :, 3], -c2w[:, :, 2])
    centres = c2w[:, :, 3]
    spread = float(np.linalg.norm(centres - target, axis=1).mean()) if len(centres) else 1.0
    return SceneLayout(up, target, max(0.05 * spread, 1e-3))


def nearest_point_to_axes(origins: np.ndarray, directions: np.ndarray) -> np.ndarray:
    """Least-squares point closest to the lines ``origins + t directions``; the cameras' mean centre when the lines
    are (nearly) parallel, as in a forward-facing capture, then moved one spread ahead along the mean axis."""
    d = directions / np.linalg.norm(directions, axis=1, keepdims=True)
    projectors = np.eye(3)[None] - d[:, :, None] * d[:, None, :]
    a = projectors.sum(axis=0)
    b = (projectors @ origins[:, :, None]).sum(axis=0)[:, 0]
    if len(origins) >= 2 and np.linalg.cond(a) < 1e6:
        return np.linalg.solve(a, b)
    centre = origins.mean(axis=0)
    mean_axis = d.mean(axis=0)
    return centre + mean_axis / max(np.linalg.norm(mean_axis), 1e-9)


def wxyz_from_rotation(rotation: np.ndarray) -> np.ndarray:
    """Unit quaternion (w, x, y, z) of a [3, 3] rotation (Shepperd's method: stable for every angle)."""
    m = np.asarray(rotation, dtype=np.float64)
    trace = np.trace(m)
    if trace > 0:
        s = 2.0 * np.sqrt(trace + 1.0)
        q = [0.25 * s, (m[2, 1] - m[1, 2]) / s, (m[0, 2] - m[2, 0]) / s, (m[1, 0] - m[0, 1]) / s]
    else:
        i = int(np.argmax(np.diag(m)))
        j, k = (i + 1) % 3, (i + 2) % 3
        s = 2.0 * np.sqrt(1.0 + m[i, i] - m[j, j] - m[k, k])
        q = [0.0, 0.0, 0.0, 0.0]
        q[0] = (m[k, j] - m[j, k]) / s
        q[1 + i] = 0.25 * s
        q[1 + j] = (m[j, i] + m[i, j]) / s
        q[1 + k] = (m[k, i] + m[i, k]) / s
    q_arr = np.array(q)
    return q_arr / np.linalg.norm(q_arr)


def _thumbnail(image: np.ndarray) -> np.ndarray:
    """uint8 RGB [h, w, 3] of a dataset image (premultiplied RGBA floats), subsampled to the frustum size."""
    stride = max(1, max(image.shape[:2]) // FRUSTUM_IMAGE_SIDE)
    small = image[::stride, ::stride]
    alpha = small[..., 3:4]
    return to_uint8(small[..., :3] + (1.0 - alpha))  # on white, as Blender scenes are shown


def add_cameras(
    scene: viser.SceneApi,
    name: str,
    outputs: DataparserOutputs,
    color: tuple[int, int, int],
    scale: float,
    with_images: bool,
) -> list[viser.CameraFrustumHandle]:
    """One frustum per view of a split under ``/name``, labelled with the view's name."""
    cameras = outputs.cameras
    images = outputs.images.detach().cpu().numpy() if with_images else None
    handles = []
    for i, view_name in enumerate(outputs.image_names):
        view = camera_from_dataset(cameras, i)
        rotation = view.camera_to_world[:, :3] @ OPENCV_TO_OPENGL  # viser draws frustums in OpenCV axes
        handle = scene.add_camera_frustum(
            f"/{name}/{view_name}",
            fov=view.fov_y,
            aspect=view.width / view.height,
            scale=scale,
            color=color,
            image=None if images is None else _thumbnail(images[i]),
            wxyz=wxyz_from_rotation(rotation),
            position=view.camera_to_world[:, 3],
            thickness=0.03 * scale if with_images else 0.015 * scale,
        )
        handles.append(handle)
    return handles


def held_out_views(parser: DataParser) -> DataparserOutputs | None:
    """The test split's views, or None when the scene has none (a capture without a held-out split)."""
    try:
        outputs = parser.get_outputs("test")
    except UserError:
        return None
    return outputs if len(outputs.cameras) > 0 else None


def add_test_views(
    server: viser.ViserServer, test: DataparserOutputs, layout: SceneLayout
) -> list[viser.CameraFrustumHandle]:
    """The held-out views: smaller, thinner, blue, without pictures (they were never seen in training)."""
    if len(test.cameras) == 0:
        return []
    return add_cameras(server.scene, "test views", test, TEST_COLOR, 0.6 * layout.frustum_scale, with_images=False)


def build_scene(
    server: viser.ViserServer, train: DataparserOutputs, test: DataparserOutputs | None
) -> tuple[SceneLayout, list[viser.CameraFrustumHandle]]:
    """Frustums of the training views (with images) and the test views, the scene's up, and the first camera."""
    layout = scene_layout(train.cameras)
    server.scene.set_up_direction(tuple(layout.up))
    frustums = add_cameras(server.scene, "training views", train, TRAIN_COLOR, layout.frustum_scale, with_images=True)
    if test is not None:
        frustums += add_test_views(server, test, layout)
    first = camera_from_dataset(train.cameras, 0)
    server.initial_camera.position = tuple(start_position(first.camera_to_world[:, 3], layout))
    server.initial_camera.look_at = tuple(layout.target)
    server.initial_camera.up = tuple(layout.up)
    server.initial_camera.fov = first.fov_y
    return layout, frustums


START_TURN_DEG = 20.0
"""How far the first view turns away from the first training camera about the scene's up axis: from exactly there,
that camera's frustum picture would fill the screen and hide the render."""


def start_position(training_centre: np.ndarray, layout: SceneLayout, turn_deg: float = START_TURN_DEG) -> np.ndarray:
    """A training camera's centre turned ``turn_deg`` about the up axis through the target (same distance)."""
    offset = np.asarray(training_centre, dtype=np.float64) - layout.target
    up, angle = layout.up, np.deg2rad(turn_deg)
    turned = offset * np.cos(angle) + np.cross(up, offset) * np.sin(angle) + up * (up @ offset) * (1 - np.cos(angle))
    return layout.target + turned
