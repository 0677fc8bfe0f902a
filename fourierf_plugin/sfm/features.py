"""SIFT features of every photo into COLMAP's database, on the CPU."""

from __future__ import annotations

from pathlib import Path
from types import ModuleType
from typing import Literal

SfmCameraModel = Literal["OPENCV", "PINHOLE", "SIMPLE_RADIAL", "OPENCV_FISHEYE"]


def extract_features(
    pycolmap: ModuleType,
    database: Path,
    image_dir: Path,
    image_names: list[str],
    camera_model: SfmCameraModel = "OPENCV",
    single_camera: bool = True,
    max_image_size: int = 1600,
    max_num_features: int = 8192,
    threads: int | None = None,
) -> None:
    """Detect and describe SIFT features of ``image_names`` (files in ``image_dir``) into ``database``.

    ``single_camera``: one shared camera (one phone, one zoom), the usual capture; otherwise photos of one size and
    EXIF focal length share a camera. ``max_image_size`` caps the longer side SIFT sees (COLMAP scales the
    keypoints back to full resolution, so the poses and intrinsics are for the full-size photos). ``threads``: CPU
    threads (None: all cores).
    """
    reader = pycolmap.ImageReaderOptions()
    reader.camera_model = camera_model
    extraction = pycolmap.FeatureExtractionOptions()
    extraction.max_image_size = max_image_size if max_image_size > 0 else -1
    extraction.sift.max_num_features = max_num_features
    extraction.use_gpu = False
    if threads is not None:
        extraction.num_threads = threads
    pycolmap.extract_features(
        database,
        image_dir,
        image_names=image_names,
        camera_mode=pycolmap.CameraMode.SINGLE if single_camera else pycolmap.CameraMode.AUTO,
        reader_options=reader,
        extraction_options=extraction,
        device=pycolmap.Device.cpu,
    )
