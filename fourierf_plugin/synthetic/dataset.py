"""The Blender-format writer: a NeRF-synthetic scene folder that the ordinary Blender parser reads.

Beside the transforms and RGBA PNGs it saves the analytic geometry as ``geometry.json``.
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import imageio.v3 as iio
import numpy as np

from fourierf_plugin.synthetic.cameras import split_cameras
from fourierf_plugin.synthetic.render import Shading, render_view
from fourierf_plugin.synthetic.scene import SceneSpec, save_scene
from fourierf_plugin.utils.colormaps import to_uint8
from fourierf_plugin.utils.errors import fail


def check_scene_fits(
    spec: SceneSpec, cameras: np.ndarray, scene_bound: float = 1.5, near: float = 2.0, far: float = 6.0
) -> None:
    """UserError unless every primitive lies in the parser's box and between its near and far planes.

    Conservative: distances are taken to the scene's bounding box, which holds every surface point.
    """
    lo, hi = spec.bounds()
    b = scene_bound
    if (lo < -b).any() or (hi > b).any():
        fail(
            f"the scene spans {np.round(lo, 3).tolist()} .. {np.round(hi, 3).tolist()}, outside the Blender "
            f"parser's box [-{b}, {b}]^3",
            "move or shrink the primitives so that they fit inside [-1.5, 1.5]^3 (ideally [-1, 1]^3)",
        )
    corners = np.array([[x, y, z] for x in (lo[0], hi[0]) for y in (lo[1], hi[1]) for z in (lo[2], hi[2])])
    for c2w in cameras:
        eye = c2w[:3, 3]
        nearest = np.linalg.norm(np.clip(eye, lo, hi) - eye)
        farthest = np.linalg.norm(corners - eye, axis=1).max()
        if nearest < near or farthest > far:
            fail(
                f"a camera at distance {np.linalg.norm(eye):.3g} sees the scene between {nearest:.3g} and "
                f"{farthest:.3g}, outside the parser's near/far range [{near}, {far}]",
                "keep the camera radius near 4 and the scene inside [-1, 1]^3",
            )


def _check_options(
    width: int, height: int, n_train: int, n_val: int, n_test: int, camera_angle_x: float, radius: float, spp: int
) -> None:
    if width < 8 or height < 8:
        fail(f"image size {width}x{height} is too small", "use --width and --height of at least 8 pixels")
    for name, value in (("--n-train", n_train), ("--n-val", n_val), ("--n-test", n_test)):
        if value < 1:
            fail(f"{name} must be >= 1, got {value}", f"pass {name} 1 or more (every split needs a view)")
    if not 0 < camera_angle_x < math.pi:
        fail(f"--camera-angle-x must lie in (0, pi) radians, got {camera_angle_x}", "the default is 0.69")
    if not radius > 0:
        fail(f"--radius must be > 0, got {radius}", "the default is 4 (the Blender parser's near/far are 2 and 6)")
    if not 1 <= spp <= 16:
        fail(f"--samples-per-pixel must be in 1..16, got {spp}", "use 1 for hard edges or 2-4 for antialiased alpha")


def write_blender_dataset(
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
) -> Path:
    """Render ``spec`` into a NeRF-synthetic scene folder and return it.

    Writes ``transforms_{train,val,test}.json`` (frames ``./<split>/r_<i>``), 8-bit RGBA PNGs with a transparent
    background (the parser composites it on white) and ``geometry.json`` (the scene plus how it was rendered).
    Stale ``r_*.png`` from an earlier generation in the split folders are removed.
    """
    _check_options(width, height, n_train, n_val, n_test, camera_angle_x, radius, samples_per_pixel)
    if shading not in ("none", "lambert"):
        fail(f"shading must be 'none' or 'lambert', got {shading!r}", "pick one of: none, lambert")
    cameras = split_cameras(n_train, n_val, n_test, radius, seed)
    check_scene_fits(spec, np.concatenate(list(cameras.values())))
    out = Path(out_dir)
    if out.exists() and not out.is_dir():
        fail(f"output path {out} is a file", "choose a folder path for the dataset")
    out.mkdir(parents=True, exist_ok=True)
    for split, c2ws in cameras.items():
        folder = out / split
        folder.mkdir(exist_ok=True)
        for stale in folder.glob("r_*.png"):
            stale.unlink()
        frames = []
        for i, c2w in enumerate(c2ws):
            rgba = render_view(spec, c2w, width, height, camera_angle_x, shading, samples_per_pixel)
            iio.imwrite(folder / f"r_{i}.png", to_uint8(rgba))
            frames.append({"file_path": f"./{split}/r_{i}", "rotation": 0.0, "transform_matrix": c2w.tolist()})
        meta = {"camera_angle_x": camera_angle_x, "frames": frames}
        (out / f"transforms_{split}.json").write_text(json.dumps(meta, indent=2) + "\n", encoding="utf-8")
    render = {
        "width": width,
        "height": height,
        "seed": seed,
        "camera_angle_x": camera_angle_x,
        "radius": radius,
        "shading": shading,
        "samples_per_pixel": samples_per_pixel,
        "views": {s: len(c) for s, c in cameras.items()},
    }
    save_scene(spec, out / "geometry.json", extra={"render": render})
    return out
