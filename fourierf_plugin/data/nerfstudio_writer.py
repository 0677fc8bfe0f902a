"""A :class:`~fourierf_plugin.data.capture.Capture` written as nerfstudio's ``transforms.json``, and an LLFF scene
read as a capture so that it can be written that way too.

Why: ``transforms.json`` is the file the nerfstudio ecosystem trains on (``ns-process-data`` writes it, the
``nerfstudio-data`` parser reads it), so the output of ``fourierf-process-data`` also works in nerfstudio itself, and
an LLFF scene written this way lets the two parsers be compared on the same photos and poses.
"""

from __future__ import annotations

import json
import os
from pathlib import Path
from typing import Any

import imageio.v3 as iio
import numpy as np

from fourierf_plugin.data.capture import DISTORTION_KEYS, Capture, Frame, Intrinsics
from fourierf_plugin.data.parsers.llff import list_images, load_poses_bounds, to_opengl
from fourierf_plugin.utils.errors import fail

DEPTH_BOUNDS_KEY = "depth_bounds"
"""Our extension key of a frame: the metric [near, far] of what the camera sees (LLFF's bounds), when known."""
_MODEL_DISTORTION: dict[str, tuple[str, ...]] = {
    "PINHOLE": (),
    "SIMPLE_PINHOLE": (),
    "OPENCV": ("k1", "k2", "k3", "p1", "p2"),
    "OPENCV_FISHEYE": ("k1", "k2", "k3", "k4"),
}


def intrinsics_json(intr: Intrinsics) -> dict[str, Any]:
    """nerfstudio's keys for one camera: size, focal lengths, principal point, model and its distortion terms."""
    out: dict[str, Any] = {
        "w": int(intr.width),
        "h": int(intr.height),
        "fl_x": float(intr.fx),
        "fl_y": float(intr.fy),
        "cx": float(intr.cx),
        "cy": float(intr.cy),
        "camera_model": intr.camera_model,
    }
    coefficients = dict(zip(DISTORTION_KEYS, intr.distortion, strict=True))
    out.update({key: float(coefficients[key]) for key in _MODEL_DISTORTION[intr.camera_model]})
    return out


def relative_posix(path: Path, folder: Path) -> str:
    """``path`` relative to ``folder`` in forward-slash form (nerfstudio joins it onto the json's folder)."""
    return Path(os.path.relpath(Path(path).resolve(), Path(folder).resolve())).as_posix()


def write_point_cloud(points: np.ndarray, path: Path, colors: np.ndarray | None = None) -> Path:
    """The sparse points as a PLY point cloud (what nerfstudio's ``ply_file_path`` names)."""
    import trimesh  # imported lazily: slow to import and only needed here

    path.parent.mkdir(parents=True, exist_ok=True)
    cloud = trimesh.PointCloud(np.asarray(points, dtype=np.float64), colors=colors)
    cloud.export(path)
    return path


def transforms_dict(capture: Capture, folder: Path, ply_file: str | None = None) -> dict[str, Any]:
    """The ``transforms.json`` content for a json in ``folder``; shared intrinsics go to the top level."""
    if not capture.frames:
        fail(f"{capture.source}: the capture has no frames to write", "register at least one image first")
    shared = all(f.intrinsics == capture.frames[0].intrinsics for f in capture.frames)
    out: dict[str, Any] = intrinsics_json(capture.frames[0].intrinsics) if shared else {}
    frames = []
    for frame in capture.frames:
        entry: dict[str, Any] = {
            "file_path": relative_posix(frame.image_path, folder),
            "transform_matrix": np.asarray(frame.camera_to_world, dtype=np.float64).tolist(),
        }
        if not shared:
            entry.update(intrinsics_json(frame.intrinsics))
        if frame.mask_path is not None:
            entry["mask_path"] = relative_posix(frame.mask_path, folder)
        if frame.depth_bounds is not None:
            entry[DEPTH_BOUNDS_KEY] = [float(frame.depth_bounds[0]), float(frame.depth_bounds[1])]
        frames.append(entry)
    out["frames"] = frames
    if capture.applied_transform is not None:
        out["applied_transform"] = np.asarray(capture.applied_transform, dtype=np.float64)[:3].tolist()
    if ply_file is not None:
        out["ply_file_path"] = ply_file
    for split, names in (capture.splits or {}).items():
        out[f"{split}_filenames"] = list(names)
    return out


def write_transforms(
    capture: Capture, path: Path, ply_name: str | None = "sparse_pc.ply", point_colors: np.ndarray | None = None
) -> Path:
    """Write ``capture`` as nerfstudio's ``transforms.json`` at ``path`` (and its points as ``ply_name`` beside it,
    when it has any); returns ``path``. Image and mask paths are stored relative to the json's folder."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    ply_file = None
    if ply_name is not None and len(capture.points):
        write_point_cloud(capture.points, path.parent / ply_name, point_colors)
        ply_file = ply_name
    content = transforms_dict(capture, path.parent, ply_file)
    path.write_text(json.dumps(content, indent=2))
    return path


# ---------------------------------------------------------------------------------------------------------------
# LLFF -> Capture


def llff_image_folder(scene: Path) -> Path:
    """The highest-resolution photo folder of an LLFF scene: ``images/``, else ``images_<k>`` with the smallest k."""
    downscaled = sorted(
        (p for p in scene.glob("images_*") if p.is_dir() and p.name.split("_", 1)[1].isdigit()),
        key=lambda p: int(p.name.split("_", 1)[1]),
    )
    candidates = [scene / "images", *downscaled]
    for folder in candidates:
        if folder.is_dir() and list_images(folder):
            return folder
    fail(f"{scene} has no images/ or images_<k>/ folder with photos", "an LLFF scene holds images_8/ (or images/)")


def capture_from_llff(scene_dir: Path, image_folder: str | None = None) -> Capture:
    """An LLFF scene (``poses_bounds.npy`` + photos) as a capture in LLFF's own world frame, OpenGL camera axes.

    ``image_folder`` (e.g. ``"images_8"``) picks the photos; by default the highest-resolution folder present. The
    focal length of ``poses_bounds.npy`` (full resolution) is scaled to those photos; the principal point is their
    centre, as LLFF assumes. The per-image depth bounds come from the file.
    """
    scene = Path(scene_dir)
    if not scene.is_dir():
        fail(f"LLFF scene folder not found: {scene}", "pass the folder holding poses_bounds.npy and images_8/")
    pb_path = scene / "poses_bounds.npy"
    raw, hwf, bounds = load_poses_bounds(pb_path)
    folder = scene / image_folder if image_folder is not None else llff_image_folder(scene)
    if not folder.is_dir():
        fail(
            f"{folder} not found",
            f"choose a photo folder of {scene} (found: {sorted(p.name for p in scene.glob('images*'))})",
        )
    files = list_images(folder)
    if len(files) != raw.shape[0]:
        fail(
            f"{pb_path} has {raw.shape[0]} poses but {folder} has {len(files)} images",
            "the poses and images must match one to one: restore the missing images",
        )
    c2w = to_opengl(raw)
    frames = []
    for i, file in enumerate(files):
        try:
            height, width = iio.improps(file).shape[:2]
        except Exception as err:  # any decoder failure on a user's file is a user-fixable problem
            fail(f"cannot read image {file} ({err})", "check that the file is a valid PNG or JPEG")
        full_h, full_w, focal = hwf[i]
        scale = width / full_w
        if abs(height / full_h - scale) > 0.01:
            fail(
                f"{file} is {width}x{height} but {pb_path} row {i} describes a {full_w:g}x{full_h:g} photo "
                "(a different aspect ratio)",
                "use the photos poses_bounds.npy was computed for",
            )
        pose = np.eye(4)
        pose[:3] = c2w[i]
        intr = Intrinsics(
            fx=focal * scale, fy=focal * scale, cx=width / 2.0, cy=height / 2.0, width=width, height=height
        )
        frames.append(Frame(file, pose, intr, depth_bounds=(float(bounds[i, 0]), float(bounds[i, 1]))))
    return Capture(frames=frames, source=pb_path)
