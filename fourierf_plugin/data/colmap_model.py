"""A COLMAP sparse model (``cameras``, ``images``, ``points3D`` in the text or the binary format) read with our own
small readers, and turned into a :class:`~fourierf_plugin.data.capture.Capture`.

Why our own readers: a model written by the COLMAP binary, by ``ns-process-data`` or by ``fourierf-process-data``
can then be trained on without the optional ``pycolmap`` package. The poses follow nerfstudio's ``colmap_to_json``
exactly (so a scene gives the same world frame through ``colmap-data`` and through a ``transforms.json``): COLMAP's
world-to-camera (OpenCV axes) is inverted, the camera axes flipped to OpenGL, and the world turned so that COLMAP's
"up" guess (-y) becomes +z; that turn is recorded as ``applied_transform`` and applied to the points as well.
"""

from __future__ import annotations

import re
import struct
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from fourierf_plugin.data.capture import Capture, Frame, Intrinsics
from fourierf_plugin.utils.errors import fail

# Every COLMAP camera model id: (name, number of parameters); the binary format needs the count to read on.
COLMAP_MODELS: dict[int, tuple[str, int]] = {
    0: ("SIMPLE_PINHOLE", 3),
    1: ("PINHOLE", 4),
    2: ("SIMPLE_RADIAL", 4),
    3: ("RADIAL", 5),
    4: ("OPENCV", 8),
    5: ("OPENCV_FISHEYE", 8),
    6: ("FULL_OPENCV", 12),
    7: ("FOV", 5),
    8: ("SIMPLE_RADIAL_FISHEYE", 4),
    9: ("RADIAL_FISHEYE", 5),
    10: ("THIN_PRISM_FISHEYE", 12),
    11: ("RAD_TAN_THIN_PRISM_FISHEYE", 16),
    12: ("SIMPLE_DIVISION", 4),
    13: ("DIVISION", 5),
    14: ("SIMPLE_FISHEYE", 3),
    15: ("FISHEYE", 4),
    16: ("EUCM", 6),
    17: ("EQUIRECTANGULAR", 2),
}
PARAM_COUNTS: dict[str, int] = {name: count for name, count in COLMAP_MODELS.values()}
SUPPORTED_MODELS: tuple[str, ...] = (
    "SIMPLE_PINHOLE",
    "PINHOLE",
    "SIMPLE_RADIAL",
    "RADIAL",
    "OPENCV",
    "OPENCV_FISHEYE",
    "FULL_OPENCV",
    "SIMPLE_RADIAL_FISHEYE",
    "RADIAL_FISHEYE",
    "SIMPLE_FISHEYE",
    "FISHEYE",
)
NERFSTUDIO_WORLD = np.array([[1.0, 0, 0, 0], [0, 0, 1, 0], [0, -1, 0, 0], [0, 0, 0, 1]])
"""nerfstudio's world change for COLMAP models (rows y and z swapped, then z negated): COLMAP's up (-y) -> +z."""
_MODEL_FIX = "point at a COLMAP sparse model folder (cameras, images and points3D as .bin or .txt, e.g. sparse/0)"


@dataclass(frozen=True)
class ColmapCamera:
    camera_id: int
    model: str
    width: int
    height: int
    params: tuple[float, ...]


@dataclass(frozen=True)
class ColmapImage:
    """One registered image: COLMAP's world-to-camera rotation (quaternion w, x, y, z) and translation (OpenCV)."""

    image_id: int
    qvec: tuple[float, float, float, float]
    tvec: tuple[float, float, float]
    camera_id: int
    name: str


@dataclass
class ColmapModel:
    """A sparse model as COLMAP stores it. Observations are flat: point index and image id of each track element."""

    folder: Path
    cameras: dict[int, ColmapCamera]
    images: dict[int, ColmapImage]
    points: np.ndarray  # [P, 3] float64, COLMAP's world frame
    colors: np.ndarray  # [P, 3] uint8
    errors: np.ndarray  # [P] mean reprojection error of each point, pixels
    observation_points: np.ndarray  # [M] int64: index into ``points``
    observation_images: np.ndarray  # [M] int64: image id

    def mean_reprojection_error(self) -> float:
        """Pixels, from the stored per-point errors weighted by track length (NaN when the model has no points)."""
        if not len(self.observation_points):
            return float("nan")
        return float(self.errors[self.observation_points].mean())


# ---------------------------------------------------------------------------------------------------------------
# reading


def model_format(folder: Path) -> str:
    """``"bin"`` or ``"txt"``: the format whose cameras and images files are both in ``folder``."""
    folder = Path(folder)
    if not folder.is_dir():
        fail(f"COLMAP model folder not found: {folder}", _MODEL_FIX)
    for ext in ("bin", "txt"):
        if (folder / f"cameras.{ext}").is_file() and (folder / f"images.{ext}").is_file():
            return ext
    present = sorted(p.name for p in folder.iterdir())
    fail(
        f"{folder} holds no COLMAP model: cameras.bin + images.bin or cameras.txt + images.txt are missing "
        f"(found: {present[:8] or 'nothing'})",
        _MODEL_FIX,
    )


def read_model(folder: Path) -> ColmapModel:
    """Read the sparse model in ``folder`` (binary preferred when both are present); points3D is optional."""
    folder = Path(folder)
    ext = model_format(folder)
    reader = _BinaryReader if ext == "bin" else _TextReader
    cameras = reader.cameras(folder / f"cameras.{ext}")
    images = reader.images(folder / f"images.{ext}")
    points_file = folder / f"points3D.{ext}"
    if points_file.is_file():
        ids, points, colors, errors, obs_point_ids, obs_images = reader.points(points_file)
    else:
        ids, points, colors, errors = np.zeros(0, np.int64), np.zeros((0, 3)), np.zeros((0, 3), np.uint8), np.zeros(0)
        obs_point_ids, obs_images = np.zeros(0, np.int64), np.zeros(0, np.int64)
    sorter = np.argsort(ids, kind="stable")
    obs_points = sorter[np.searchsorted(ids, obs_point_ids, sorter=sorter)] if len(ids) else np.zeros(0, np.int64)
    for image in images.values():
        if image.camera_id not in cameras:
            fail(
                f"{folder}: image {image.name!r} (id {image.image_id}) uses camera {image.camera_id}, which "
                f"cameras.{ext} does not list",
                "the model is incomplete: re-export it from COLMAP",
            )
    return ColmapModel(folder, cameras, images, points, colors, errors, obs_points, obs_images)


class _TextReader:
    """COLMAP's text format: one record per line, ``#`` comments; images take two lines (pose, then 2D points)."""

    @staticmethod
    def _records(path: Path) -> list[tuple[int, list[str]]]:
        try:
            lines = path.read_text().splitlines()
        except (OSError, UnicodeDecodeError) as err:
            fail(f"cannot read {path} ({err})", "re-export the model from COLMAP")
        return [(n, line.split()) for n, line in enumerate(lines, 1) if line.strip() and not line.startswith("#")]

    @staticmethod
    def _bad(path: Path, line: int, what: str) -> None:
        fail(f"{path}, line {line}: {what}", "the file is corrupt or not a COLMAP model: re-export it from COLMAP")

    @classmethod
    def cameras(cls, path: Path) -> dict[int, ColmapCamera]:
        cameras = {}
        for line, tok in cls._records(path):
            try:
                cam_id, model, width, height = int(tok[0]), tok[1], int(tok[2]), int(tok[3])
                params = tuple(float(v) for v in tok[4:])
            except (IndexError, ValueError):
                cls._bad(path, line, "expected CAMERA_ID MODEL WIDTH HEIGHT PARAMS...")
            expected = PARAM_COUNTS.get(model)
            if expected is not None and len(params) != expected:
                cls._bad(path, line, f"camera model {model} takes {expected} parameters, found {len(params)}")
            cameras[cam_id] = ColmapCamera(cam_id, model, width, height, params)
        return cameras

    @classmethod
    def images(cls, path: Path) -> dict[int, ColmapImage]:
        records = cls._records(path)
        images = {}
        i = 0
        while i < len(records):
            line, tok = records[i]
            try:
                values = [float(v) for v in tok[1:8]]
                image = ColmapImage(int(tok[0]), tuple(values[:4]), tuple(values[4:7]), int(tok[8]), " ".join(tok[9:]))
            except (IndexError, ValueError):
                cls._bad(path, line, "expected IMAGE_ID QW QX QY QZ TX TY TZ CAMERA_ID NAME")
            if not image.name:
                cls._bad(path, line, "the image has no name")
            images[image.image_id] = image
            # the 2D points line follows; it may be empty (and then it was skipped as blank)
            nxt = records[i + 1] if i + 1 < len(records) else None
            i += 2 if nxt is not None and nxt[0] == line + 1 else 1
        return images

    @classmethod
    def points(cls, path: Path) -> tuple[np.ndarray, ...]:
        ids, xyz, rgb, err, obs_ids, obs_images = [], [], [], [], [], []
        for line, tok in cls._records(path):
            try:
                pid = int(tok[0])
                xyz.append([float(v) for v in tok[1:4]])
                rgb.append([int(v) for v in tok[4:7]])
                err.append(float(tok[7]))
                track = [int(v) for v in tok[8:]]
            except (IndexError, ValueError):
                cls._bad(path, line, "expected POINT3D_ID X Y Z R G B ERROR TRACK...")
            if len(track) % 2:
                cls._bad(path, line, "the track must list (IMAGE_ID, POINT2D_IDX) pairs")
            ids.append(pid)
            obs_images.extend(track[0::2])
            obs_ids.extend([pid] * (len(track) // 2))
        return (
            np.array(ids, dtype=np.int64),
            np.array(xyz, dtype=np.float64).reshape(-1, 3),
            np.array(rgb, dtype=np.uint8).reshape(-1, 3),
            np.array(err, dtype=np.float64),
            np.array(obs_ids, dtype=np.int64),
            np.array(obs_images, dtype=np.int64),
        )


class _Cursor:
    """Little-endian reads over a file's bytes that fail cleanly when the file ends early."""

    def __init__(self, path: Path) -> None:
        self.path = path
        try:
            self.data = path.read_bytes()
        except OSError as err:
            fail(f"cannot read {path} ({err.strerror or err})", "re-export the model from COLMAP")
        self.pos = 0

    def _need(self, size: int) -> None:
        if self.pos + size > len(self.data):
            fail(
                f"{self.path} ends early (byte {self.pos} of {len(self.data)}): truncated or not a COLMAP model",
                "re-export the model from COLMAP",
            )

    def take(self, fmt: str) -> tuple:
        size = struct.calcsize("<" + fmt)
        self._need(size)
        values = struct.unpack_from("<" + fmt, self.data, self.pos)
        self.pos += size
        return values

    def array(self, dtype: np.dtype, count: int) -> np.ndarray:
        size = np.dtype(dtype).itemsize * count
        self._need(size)
        out = np.frombuffer(self.data, dtype=dtype, count=count, offset=self.pos)
        self.pos += size
        return out

    def name(self) -> str:
        """A NUL-terminated UTF-8 string."""
        end = self.data.find(b"\0", self.pos)
        if end < 0:
            self._need(len(self.data) - self.pos + 1)
        text = self.data[self.pos : end].decode("utf-8", errors="replace")
        self.pos = end + 1
        return text


def _concatenated(parts: list[np.ndarray]) -> np.ndarray:
    return np.concatenate(parts).astype(np.int64) if parts else np.zeros(0, np.int64)


class _BinaryReader:
    """COLMAP's binary format (``colmap/src/colmap/scene/reconstruction_io_binary.cc``), little-endian."""

    @staticmethod
    def cameras(path: Path) -> dict[int, ColmapCamera]:
        cur = _Cursor(path)
        cameras = {}
        for _ in range(cur.take("Q")[0]):
            cam_id, model_id, width, height = cur.take("iiQQ")
            if model_id not in COLMAP_MODELS:
                fail(
                    f"{path}: camera {cam_id} has camera model id {model_id}, unknown to this reader",
                    f"convert the model to text (colmap model_converter --output_type TXT) or use one of "
                    f"{', '.join(SUPPORTED_MODELS)}",
                )
            name, count = COLMAP_MODELS[model_id]
            cameras[cam_id] = ColmapCamera(cam_id, name, width, height, cur.take("d" * count))
        return cameras

    @staticmethod
    def images(path: Path) -> dict[int, ColmapImage]:
        cur = _Cursor(path)
        images = {}
        for _ in range(cur.take("Q")[0]):
            image_id, qw, qx, qy, qz, tx, ty, tz, cam_id = cur.take("IdddddddI")
            name = cur.name()
            n_points = cur.take("Q")[0]
            cur.array(np.dtype([("x", "<f8"), ("y", "<f8"), ("id", "<i8")]), n_points)  # not needed: skip
            images[image_id] = ColmapImage(image_id, (qw, qx, qy, qz), (tx, ty, tz), cam_id, name)
        return images

    @staticmethod
    def points(path: Path) -> tuple[np.ndarray, ...]:
        cur = _Cursor(path)
        n = cur.take("Q")[0]
        ids = np.empty(n, np.int64)
        xyz = np.empty((n, 3))
        rgb = np.empty((n, 3), np.uint8)
        err = np.empty(n)
        obs_ids, obs_images = [], []
        for i in range(n):
            pid, x, y, z, r, g, b, e, track_len = cur.take("QdddBBBdQ")
            ids[i], xyz[i], rgb[i], err[i] = pid, (x, y, z), (r, g, b), e
            track = cur.array(np.dtype("<i4"), 2 * track_len)
            obs_images.append(track[0::2])
            obs_ids.append(np.full(track_len, pid, dtype=np.int64))
        return ids, xyz, rgb, err, _concatenated(obs_ids), _concatenated(obs_images)


# ---------------------------------------------------------------------------------------------------------------
# to a Capture


def qvec_to_rotation(qvec: tuple[float, float, float, float] | np.ndarray) -> np.ndarray:
    """Rotation matrix of a unit quaternion (w, x, y, z), COLMAP's order; the quaternion is normalised first."""
    w, x, y, z = np.asarray(qvec, dtype=np.float64) / np.linalg.norm(qvec)
    return np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
            [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
            [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
        ]
    )


def opengl_camera_to_world(image: ColmapImage) -> np.ndarray:
    """COLMAP's world-to-camera (OpenCV axes) -> camera-to-world with OpenGL axes, still in COLMAP's world."""
    rot = qvec_to_rotation(image.qvec)
    c2w = np.eye(4)
    c2w[:3, :3] = rot.T
    c2w[:3, 3] = -rot.T @ np.asarray(image.tvec, dtype=np.float64)
    c2w[:3, 1:3] *= -1  # camera y down / z forward -> y up / z backward
    return c2w


def intrinsics_of(camera: ColmapCamera, where: str) -> Intrinsics:
    """Our four camera models from COLMAP's: radial models become OPENCV, the fisheye family OPENCV_FISHEYE."""
    p = camera.params
    size = {"width": camera.width, "height": camera.height}
    model = camera.model
    if model == "SIMPLE_PINHOLE":
        return Intrinsics(p[0], p[0], p[1], p[2], **size, camera_model="SIMPLE_PINHOLE")
    if model == "PINHOLE":
        return Intrinsics(p[0], p[1], p[2], p[3], **size, camera_model="PINHOLE")
    if model in ("SIMPLE_RADIAL", "RADIAL"):
        k = (*p[3:], 0.0)[:2]
        return Intrinsics(p[0], p[0], p[1], p[2], **size, camera_model="OPENCV", distortion=(k[0], k[1], 0, 0, 0, 0))
    if model == "OPENCV":
        k1, k2, p1, p2 = p[4:8]
        return Intrinsics(*p[:4], **size, camera_model="OPENCV", distortion=(k1, k2, 0.0, 0.0, p1, p2))
    if model == "FULL_OPENCV" and not any(p[9:12]):  # the rational terms k4..k6 unused: plain OPENCV with k3
        k1, k2, p1, p2, k3 = p[4:9]
        return Intrinsics(*p[:4], **size, camera_model="OPENCV", distortion=(k1, k2, k3, 0.0, p1, p2))
    if model == "OPENCV_FISHEYE":
        return Intrinsics(*p[:4], **size, camera_model="OPENCV_FISHEYE", distortion=(*p[4:8], 0.0, 0.0))
    if model in ("SIMPLE_RADIAL_FISHEYE", "RADIAL_FISHEYE"):  # theta_d = theta (1 + k1 theta^2 + k2 theta^4)
        k = (*p[3:], 0.0)[:2]
        return Intrinsics(p[0], p[0], p[1], p[2], **size, camera_model="OPENCV_FISHEYE", distortion=(*k, 0, 0, 0, 0))
    if model == "SIMPLE_FISHEYE":  # equidistant, no distortion
        return Intrinsics(p[0], p[0], p[1], p[2], **size, camera_model="OPENCV_FISHEYE")
    if model == "FISHEYE":
        return Intrinsics(*p[:4], **size, camera_model="OPENCV_FISHEYE")
    detail = " with the rational terms k4..k6" if model == "FULL_OPENCV" else ""
    fail(
        f"{where}: camera {camera.camera_id} uses the COLMAP camera model {model}{detail}, which fourierf cannot "
        f"handle (supported: {', '.join(SUPPORTED_MODELS)})",
        "re-run COLMAP with --ImageReader.camera_model OPENCV (or OPENCV_FISHEYE for fisheye lenses), or undistort "
        "the images first (colmap image_undistorter) and use the PINHOLE model it writes",
    )


MIN_TRACK_LENGTH = 3
"""Depth bounds count the points seen in at least this many photos: a point matched in only two is the likeliest to
be a false match, and one such point in front of the scene would set its nearest bound, and so a forward-facing
scene's scale. An image that observes no such point falls back to all the points it observes."""


def depth_bounds(
    model: ColmapModel,
    near_percentile: float = 0.1,
    far_percentile: float = 99.9,
    min_track_length: int = MIN_TRACK_LENGTH,
) -> dict[int, tuple]:
    """(near, far) per image id as LLFF's imgs2poses computes them, percentiles of the depths of the points the image
    observes, over the points seen in ``min_track_length`` photos or more. Images that observe no point, or whose
    near bound is not in front of the camera, are left out."""
    out: dict[int, tuple[float, float]] = {}
    track_length = np.bincount(model.observation_points, minlength=len(model.points))
    order = np.argsort(model.observation_images, kind="stable")
    image_ids = model.observation_images[order]
    point_idx = model.observation_points[order]
    starts = np.searchsorted(image_ids, list(model.images), side="left")
    ends = np.searchsorted(image_ids, list(model.images), side="right")
    for (image_id, image), lo, hi in zip(model.images.items(), starts, ends, strict=True):
        if hi <= lo:
            continue
        observed = point_idx[lo:hi]
        tracked = observed[track_length[observed] >= min_track_length]
        rot = qvec_to_rotation(image.qvec)
        depths = model.points[tracked if len(tracked) else observed] @ rot[2] + image.tvec[2]  # OpenCV z: ahead
        near, far = np.percentile(depths, [near_percentile, far_percentile])
        if 0 < near < far:
            out[image_id] = (float(near), float(far))
    return out


def _natural_key(name: str) -> list:
    return [int(tok) if tok.isdigit() else tok.lower() for tok in re.split(r"(\d+)", name)]


def capture_from_model(model: ColmapModel, images_dir: Path) -> Capture:
    """The registered images of ``model`` as a :class:`Capture` in nerfstudio's world frame (see the module doc).

    Frames are in natural name order; every image file must be in ``images_dir`` (under the name COLMAP gives it).
    """
    where = str(model.folder)
    if not model.images:
        fail(
            f"the COLMAP model {where} has no registered images",
            "structure-from-motion registered nothing: re-run it with more overlapping photos "
            "(fourierf-process-data images), or point at another model folder (sparse/1, ...)",
        )
    images_dir = Path(images_dir)
    if not images_dir.is_dir():
        fail(
            f"image folder not found: {images_dir} (the images of the COLMAP model {where})",
            "pass --images-path pointing at the folder COLMAP ran on (relative to --data)",
        )
    ordered = sorted(model.images.values(), key=lambda im: _natural_key(im.name))
    missing = [im.name for im in ordered if not (images_dir / im.name).is_file()]
    if missing:
        fail(
            f"{len(missing)} of the {len(ordered)} images of the COLMAP model {where} are not in {images_dir}: "
            f"{', '.join(missing[:5])}{' ...' if len(missing) > 5 else ''}",
            "restore the missing photos, or pass --images-path pointing at the folder COLMAP ran on",
        )
    bounds = depth_bounds(model)
    intrinsics = {cam_id: intrinsics_of(cam, f"{where}/cameras") for cam_id, cam in model.cameras.items()}
    frames = []
    for image in ordered:
        if not (np.isfinite(image.qvec).all() and np.isfinite(image.tvec).all()) or not np.linalg.norm(image.qvec):
            fail(
                f"{where}: image {image.name!r} (id {image.image_id}) has a non-finite pose",
                "the model is corrupt: re-run structure-from-motion",
            )
        frames.append(
            Frame(
                image_path=images_dir / image.name,
                camera_to_world=NERFSTUDIO_WORLD @ opengl_camera_to_world(image),
                intrinsics=intrinsics[image.camera_id],
                depth_bounds=bounds.get(image.image_id),
            )
        )
    points = model.points @ NERFSTUDIO_WORLD[:3, :3].T
    return Capture(frames=frames, source=model.folder, points=points, applied_transform=NERFSTUDIO_WORLD[:3].copy())
