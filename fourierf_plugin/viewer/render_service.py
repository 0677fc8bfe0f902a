"""What the viewer draws: one camera, at a pair of Fourier cutoffs, as an RGB, depth or accumulation picture.

Pure functions of a model and a camera (no viser, no threads), so the browser, the benchmark and the tests share one
path: the viewer's camera becomes a one-camera :class:`Cameras`, whose rays come from the package's own ray code
(NDC for forward-facing scenes, as in training), rendered by the model's eval path at the requested cutoffs.
"""

from __future__ import annotations

import dataclasses
import math
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from typing import TYPE_CHECKING, Literal

import numpy as np
import torch
import torch.nn.functional as F

from fourierf_plugin.cameras.cameras import Cameras
from fourierf_plugin.data.datamanager import camera_rays
from fourierf_plugin.utils.colormaps import colorize_accumulation, colorize_depth, depth_range, to_uint8

if TYPE_CHECKING:
    from fourierf_plugin.models.fourierf import FourieRFModel

Output = Literal["rgb", "depth", "accumulation"]
OUTPUTS: tuple[Output, ...] = ("rgb", "depth", "accumulation")

OPENCV_TO_OPENGL = np.diag([1.0, -1.0, -1.0])
"""Flips camera y and z: viser (OpenCV: y down, looking down +z) <-> the package (OpenGL: y up, looking down -z)."""


@dataclass(frozen=True)
class ViewCamera:
    """A pinhole camera in the package's OpenGL convention, with square pixels and the principal point centred."""

    camera_to_world: np.ndarray
    """[3, 4]: rotation columns (x right, y up, z backwards) and the centre."""
    fov_y: float
    """Vertical field of view, radians."""
    width: int
    height: int

    @property
    def focal(self) -> float:
        return 0.5 * self.height / math.tan(0.5 * self.fov_y)

    def resized(self, width: int, height: int) -> ViewCamera:
        """The same view at another resolution (the field of view is kept, so the picture only gets finer)."""
        return ViewCamera(self.camera_to_world, self.fov_y, width, height)

    def as_cameras(self) -> Cameras:
        """A one-camera set, so rays come from :meth:`Cameras.generate_rays` like any dataset view."""

        def one(value: float) -> torch.Tensor:
            return torch.tensor([value], dtype=torch.float32)

        c2w = torch.as_tensor(self.camera_to_world, dtype=torch.float32).reshape(1, 3, 4)
        f = self.focal
        return Cameras(c2w, one(f), one(f), one(0.5 * self.width), one(0.5 * self.height), self.width, self.height)


def rotation_from_wxyz(wxyz: np.ndarray) -> np.ndarray:
    """[3, 3] rotation of a unit quaternion (w, x, y, z); normalised first, as a browser sends rounded floats."""
    w, x, y, z = np.asarray(wxyz, dtype=np.float64) / np.linalg.norm(wxyz)
    return np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
            [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
            [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
        ]
    )


def camera_from_opencv_pose(
    wxyz: np.ndarray, position: np.ndarray, fov_y: float, aspect: float, long_side: int
) -> ViewCamera:
    """The camera a browser reports (viser: OpenCV axes, vertical fov, width/height aspect) at ``long_side`` pixels
    along its longer image axis."""
    rotation = rotation_from_wxyz(wxyz) @ OPENCV_TO_OPENGL
    c2w = np.concatenate([rotation, np.asarray(position, dtype=np.float64).reshape(3, 1)], axis=1)
    width, height = fit_size(aspect, long_side)
    return ViewCamera(c2w, float(fov_y), width, height)


def camera_from_dataset(cameras: Cameras, index: int) -> ViewCamera:
    """Dataset camera ``index`` as a :class:`ViewCamera` (its vertical field of view, centred principal point)."""
    fov_y = 2.0 * math.atan(0.5 * cameras.height / float(cameras.fy[index]))
    c2w = cameras.camera_to_worlds[index].detach().cpu().double().numpy()
    return ViewCamera(c2w, fov_y, cameras.width, cameras.height)


def fit_size(aspect: float, long_side: int) -> tuple[int, int]:
    """(width, height) with ``long_side`` pixels along the longer axis and the given width/height aspect."""
    if not (math.isfinite(aspect) and aspect > 0):
        aspect = 1.0
    if aspect >= 1.0:
        return long_side, max(1, round(long_side / aspect))
    return max(1, round(long_side * aspect)), long_side


def preview_size(width: int, height: int, factor: float = 0.25, min_side: int = 32) -> tuple[int, int]:
    """The quick picture shown while the camera moves: ``factor`` of each side (at least ``min_side`` pixels on the
    longer one), never larger than the full picture."""
    scale = max(factor, min_side / max(width, height, 1))
    scale = min(scale, 1.0)
    return max(1, round(width * scale)), max(1, round(height * scale))


@dataclass(frozen=True)
class PreviewQuality:
    """How a preview (the picture shown while the camera moves) is made cheaper than the final one.

    Each knob trades a little picture for time; the final (at-rest) picture uses none of them. A longer step and the
    thresholds cost little of the picture; a smaller picture scaled up is the quickest and the blurriest.
    """

    step_scale: float = 2.0
    """Multiplies the ray-marching step (half the samples per ray at 2)."""
    early_stop_transmittance: float = 1e-2
    """A ray stops being marched once its transmittance is below this (the final render: the model's own, 1e-4)."""
    weight_threshold: float = 1e-3
    """Colour is evaluated only at samples whose compositing weight exceeds this (the final render: 1e-4)."""


@contextmanager
def preview_settings(model: FourieRFModel, quality: PreviewQuality | None) -> Iterator[None]:
    """Render ``model`` with ``quality``'s cheaper marching inside the block, then restore its own settings.

    The model reads its step ratio, early-stop transmittance and weight threshold from its config at every render,
    so the block swaps in a copy of the config with those three changed. Only for a model nothing else renders
    meanwhile: the viewer's own (drawn under ``ViewedRun.lock``)."""
    if quality is None:
        yield
        return
    own = model.config
    accel = dataclasses.replace(
        own.accel,
        early_stop_transmittance=max(own.accel.early_stop_transmittance, quality.early_stop_transmittance),
    )
    model.config = dataclasses.replace(
        own,
        step_ratio=own.step_ratio * quality.step_scale,
        weight_threshold=max(own.weight_threshold, quality.weight_threshold),
        accel=accel,
    )
    try:
        yield
    finally:
        model.config = own


@dataclass
class Rendered:
    """The three pictures of one render (each uint8 [H, W, 3]) and how long the model took."""

    rgb: np.ndarray
    depth: np.ndarray
    accumulation: np.ndarray
    seconds: float
    rendered_size: tuple[int, int] | None = None
    """(width, height) the model rendered, when smaller than the pictures (scaled up to them); None: the same."""
    depth_range: tuple[float, float] = (0.0, 1.0)
    """The depths at the low and high ends of the depth picture's colormap (its legend)."""

    def image(self, output: Output) -> np.ndarray:
        return {"rgb": self.rgb, "depth": self.depth, "accumulation": self.accumulation}[output]


RAYS_PER_BLOCK = 16384
"""Rays rendered between two checks of ``abort`` (a 256×256 preview is four blocks)."""


def render_view(
    model: FourieRFModel,
    camera: ViewCamera,
    cutoffs: tuple[float, float],
    abort: Callable[[], bool] | None = None,
    quality: PreviewQuality | None = None,
    render_size: tuple[int, int] | None = None,
    progress: Callable[[float], None] | None = None,
) -> Rendered | None:
    """Render ``camera`` with the field low-passed at ``cutoffs`` (f_density, f_color), through the model's eval path.

    ``abort`` is asked between blocks of rays; when it says yes the render stops and None is returned (the camera
    moved on: a large picture nobody will see is not finished).

    A preview passes ``quality`` (cheaper marching, ``preview_settings``) and may pass ``render_size`` (width,
    height) smaller than the camera's: the model then renders that many pixels and the pictures are scaled up
    (bilinear) to the camera's size. Without both, the render is the model's own eval render. ``progress`` is told
    the share of rays done after each block.

    The field is left prepared at ``cutoffs``: the viewer owns the model it draws (a saved run's, or the live
    viewer's private copy), and the next picture at the same cutoffs and weights then reuses the filtering and the
    lookup tables built from it (a third of a P-CPU preview's time)."""
    start = time.perf_counter()
    device = model.aabb.device
    shown = camera
    if render_size is not None and render_size != (camera.width, camera.height):
        camera = camera.resized(*render_size)
    origins, directions = camera_rays(camera.as_cameras(), 0, model.effects.ray_space)
    with torch.no_grad():
        model.field.prepare(*cutoffs)  # each block's render_rays finds these cutoffs prepared and reuses them
    parts = []
    with preview_settings(model, quality):
        for i in range(0, origins.shape[0], RAYS_PER_BLOCK):
            if abort is not None and abort():
                return None
            block = slice(i, i + RAYS_PER_BLOCK)
            rays = origins[block].to(device), directions[block].to(device)
            parts.append(model.render_rays(*rays, 0, cutoffs=cutoffs))
            if progress is not None:
                progress(min(1.0, (i + RAYS_PER_BLOCK) / origins.shape[0]))
    out = {key: torch.cat([p[key] for p in parts]) for key in ("rgb", "depth", "accumulation")}
    shape = (camera.height, camera.width)
    rgb_f = out["rgb"].view(*shape, 3).cpu()
    depth = out["depth"].view(shape).cpu()
    acc = out["accumulation"].view(shape).cpu()
    rendered_size = None
    if camera is not shown:
        rendered_size = (camera.width, camera.height)
        size = (shown.height, shown.width)
        rgb_f = _upsample(rgb_f.permute(2, 0, 1), size).permute(1, 2, 0).clamp(0.0, 1.0)
        depth, acc = _upsample(depth[None], size)[0], _upsample(acc[None], size)[0].clamp(0.0, 1.0)
    seconds = time.perf_counter() - start
    rgb = to_uint8(rgb_f)
    near, far = depth_range(depth, acc)
    depth_picture = colorize_depth(depth, acc, near, far)
    return Rendered(rgb, depth_picture, colorize_accumulation(acc), seconds, rendered_size, (near, far))


def _upsample(image: torch.Tensor, size: tuple[int, int]) -> torch.Tensor:
    """[C, h, w] -> [C, H, W], bilinear (pixel centres aligned, as a browser scales a picture)."""
    return F.interpolate(image[None], size=size, mode="bilinear", align_corners=False)[0]


def high_frequency_energy(image: np.ndarray) -> float:
    """Mean squared difference between neighbouring pixels (a picture's share of fine detail; 0 for a flat one).

    The tests and the benchmark use it to tell a low-cutoff render (smooth) from a full one."""
    grey = np.asarray(image, dtype=np.float64)
    if grey.ndim == 3:
        grey = grey.mean(axis=-1)
    dx = np.diff(grey, axis=1)
    dy = np.diff(grey, axis=0)
    return float((dx**2).mean() + (dy**2).mean()) if dx.size and dy.size else 0.0
