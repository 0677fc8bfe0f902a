"""The nerfstudio-format writer: an analytic scene as a photo capture (``transforms.json`` + ``images/``).

Why: the ``nerfstudio-data`` parser and lens distortion need a capture whose answer is known. Rendered through an
OPENCV lens, each pixel shows what the scene shows along the ray that :meth:`Cameras.generate_rays` forms for that
pixel of the distorted camera, so training on the distorted capture must reach the quality of the undistorted one
exactly when rays are undistorted correctly.

Cameras, scene checks and shading are the Blender writer's (same spirals, same focal length from
``camera_angle_x``, principal point in the image centre); only the file layout and the lens differ.
"""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any

import imageio.v3 as iio
import numpy as np
import torch

from fourierf_plugin.cameras.cameras import Cameras
from fourierf_plugin.cameras.distortion import DISTORTION_KEYS
from fourierf_plugin.synthetic.cameras import focal_length, split_cameras
from fourierf_plugin.synthetic.dataset import _check_options, check_scene_fits
from fourierf_plugin.synthetic.render import Shading, render_rays
from fourierf_plugin.synthetic.scene import SceneSpec, save_scene
from fourierf_plugin.utils.colormaps import to_uint8
from fourierf_plugin.utils.errors import fail

PHONE_LENS: dict[str, float] = {"k1": -0.12, "k2": 0.03, "p1": 1e-3, "p2": -5e-4}
"""A phone camera's barrel lens with slight decentring (COLMAP's usual estimates for phone photos)."""

WRITTEN_KEYS = ("k1", "k2", "p1", "p2")
"""Coefficients always written for OPENCV, as nerfstudio's COLMAP converter does (k3, k4 only when non-zero)."""


def capture_cameras(
    c2ws: np.ndarray, width: int, height: int, camera_angle_x: float, distortion: dict[str, float] | None = None
) -> Cameras:
    """float64 :class:`Cameras` of ``c2ws`` [N, 4, 4] with the Blender writer's intrinsics and an OPENCV lens.

    ``distortion`` maps coefficient names (k1, k2, k3, k4, p1, p2) to values; None or {} is an ideal pinhole.
    """
    n = len(c2ws)
    f = focal_length(width, camera_angle_x)

    def full(value: float) -> torch.Tensor:
        return torch.full((n,), float(value), dtype=torch.float64)

    c2w = torch.as_tensor(np.asarray(c2ws, dtype=np.float64)[:, :3, :4])
    if not distortion:
        return Cameras(c2w, full(f), full(f), full(width / 2), full(height / 2), width, height)
    coeffs = torch.tensor([[float(distortion.get(k, 0.0)) for k in DISTORTION_KEYS]] * n, dtype=torch.float64)
    return Cameras(c2w, full(f), full(f), full(width / 2), full(height / 2), width, height, "OPENCV", coeffs)


def render_camera(
    spec: SceneSpec, cameras: Cameras, index: int, shading: Shading = "none", samples_per_pixel: int = 1
) -> np.ndarray:
    """Straight-alpha RGBA float [H, W, 4] of camera ``index`` along the rays of :meth:`Cameras.generate_rays`.

    Supersampling (k x k rays per pixel) shifts the principal point by the sub-pixel offset, so every sample ray is
    still one that ``generate_rays`` forms, lens included.
    """
    k, h, w = samples_per_pixel, cameras.height, cameras.width
    premult = np.zeros((h * w, 4))
    for dv in (np.arange(k) + 0.5) / k:
        for du in (np.arange(k) + 0.5) / k:
            shifted = Cameras(
                cameras.camera_to_worlds[index : index + 1],
                cameras.fx[index : index + 1],
                cameras.fy[index : index + 1],
                cameras.cx[index : index + 1] + 0.5 - du,  # the pixel centre u + 0.5 now samples u + du
                cameras.cy[index : index + 1] + 0.5 - dv,
                w,
                h,
                cameras.camera_model,
                None if cameras.distortion is None else cameras.distortion[index : index + 1],
            )
            origins, dirs = (t.double().numpy() for t in shifted.generate_rays(0))
            premult += render_rays(spec, origins, dirs, shading)
    premult = premult.reshape(h, w, 4) / (k * k)
    alpha = premult[..., 3:]
    rgb = np.divide(premult[..., :3], alpha, out=np.zeros_like(premult[..., :3]), where=alpha > 0)
    return np.concatenate([rgb, alpha], axis=-1)


def _check_distortion(distortion: dict[str, float] | None) -> dict[str, float]:
    lens = dict(distortion or {})
    unknown = sorted(set(lens) - set(DISTORTION_KEYS))
    if unknown:
        fail(f"unknown distortion coefficients {unknown}", f"use OPENCV's {', '.join(DISTORTION_KEYS)}")
    bad = {k: v for k, v in lens.items() if not math.isfinite(float(v))}
    if bad:
        fail(f"distortion coefficients must be finite, got {bad}", "pass finite numbers")
    return {k: float(v) for k, v in lens.items()}


def write_nerfstudio_capture(
    spec: SceneSpec,
    out_dir: Path,
    width: int = 100,
    height: int = 100,
    n_train: int = 4,
    n_val: int = 4,
    n_test: int = 8,
    seed: int = 0,
    camera_angle_x: float = 0.69,
    radius: float = 4.0,
    shading: Shading = "none",
    samples_per_pixel: int = 1,
    distortion: dict[str, float] | None = None,
) -> Path:
    """Render ``spec`` into a nerfstudio capture folder and return it.

    Writes ``images/{split}_{i:03d}.png`` (8-bit RGBA, transparent background), ``transforms.json`` (shared
    intrinsics ``camera_model, fl_x, fl_y, cx, cy, w, h`` and, for a lens, ``k1 k2 p1 p2``; frames with
    ``file_path`` and OpenGL ``transform_matrix``; ``{train,val,test}_filenames``) and ``geometry.json``. With the
    same arguments and no distortion the images equal those of :func:`write_blender_dataset`. Stale PNGs in
    ``images/`` from an earlier generation are removed.
    """
    _check_options(width, height, n_train, n_val, n_test, camera_angle_x, radius, samples_per_pixel)
    if shading not in ("none", "lambert"):
        fail(f"shading must be 'none' or 'lambert', got {shading!r}", "pick one of: none, lambert")
    lens = _check_distortion(distortion)
    cameras_by_split = split_cameras(n_train, n_val, n_test, radius, seed)
    c2ws = np.concatenate(list(cameras_by_split.values()))
    check_scene_fits(spec, c2ws)
    cameras = capture_cameras(c2ws, width, height, camera_angle_x, lens)
    try:
        cameras.generate_rays(0)  # the lens must be invertible over the whole image (same for every camera)
    except ValueError as err:
        fail(f"the distortion {lens} cannot be undistorted over a {width}x{height} image: {err}", "use a milder lens")
    out = Path(out_dir)
    if out.exists() and not out.is_dir():
        fail(f"output path {out} is a file", "choose a folder path for the capture")
    images = out / "images"
    images.mkdir(parents=True, exist_ok=True)
    for stale in images.glob("*.png"):
        stale.unlink()
    frames, names = [], {}
    index = 0
    for split, split_c2ws in cameras_by_split.items():
        names[split] = []
        for i, c2w in enumerate(split_c2ws):
            name = f"images/{split}_{i:03d}.png"
            iio.imwrite(out / name, to_uint8(render_camera(spec, cameras, index, shading, samples_per_pixel)))
            frames.append({"file_path": name, "transform_matrix": c2w.tolist()})
            names[split].append(name)
            index += 1
    meta = _intrinsics_json(cameras, lens) | {"frames": frames} | {f"{s}_filenames": n for s, n in names.items()}
    (out / "transforms.json").write_text(json.dumps(meta, indent=2) + "\n", encoding="utf-8")
    render = {
        "format": "nerfstudio",
        "width": width,
        "height": height,
        "seed": seed,
        "camera_angle_x": camera_angle_x,
        "radius": radius,
        "shading": shading,
        "samples_per_pixel": samples_per_pixel,
        "camera_model": cameras.camera_model,
        "distortion": lens,
        "views": {s: len(c) for s, c in cameras_by_split.items()},
    }
    save_scene(spec, out / "geometry.json", extra={"render": render})
    return out


def _intrinsics_json(cameras: Cameras, lens: dict[str, float]) -> dict[str, Any]:
    """nerfstudio's shared-intrinsics keys (as ``ns-process-data`` writes them)."""
    meta: dict[str, Any] = {
        "camera_model": cameras.camera_model,
        "fl_x": float(cameras.fx[0]),
        "fl_y": float(cameras.fy[0]),
        "cx": float(cameras.cx[0]),
        "cy": float(cameras.cy[0]),
        "w": cameras.width,
        "h": cameras.height,
    }
    if cameras.camera_model == "OPENCV":
        meta |= {k: lens.get(k, 0.0) for k in DISTORTION_KEYS if k in WRITTEN_KEYS or lens.get(k, 0.0) != 0.0}
    return meta
