"""The structure-from-motion stages in order: features, matching, mapping; the largest model saved as
``colmap/sparse/0`` (COLMAP's binary format), the database kept beside it for reruns and inspection.

Progress inside a stage: extraction and matching give no callback, so they print a heartbeat with the time spent
(their database is never read while COLMAP writes it: a second copy of SQLite in the process breaks its file locks);
mapping calls back per registered photo.
"""

from __future__ import annotations

import shutil
from dataclasses import dataclass
from pathlib import Path
from types import ModuleType

from fourierf_plugin.sfm.colmap_library import import_pycolmap
from fourierf_plugin.sfm.features import SfmCameraModel, extract_features
from fourierf_plugin.sfm.mapping import run_incremental_mapping
from fourierf_plugin.sfm.matching import MatchingMode, match_features, pair_count, resolve_matching
from fourierf_plugin.sfm.photos import image_size
from fourierf_plugin.sfm.progress import StageDisplay
from fourierf_plugin.utils.errors import fail

OVERLAP_ADVICE = (
    "photos register when each one shares most of its view (60-80 %) with a neighbour: take more photos from "
    "nearby viewpoints, move around the subject instead of turning on the spot, avoid blurry, textureless or "
    "reflective views, or keep fewer, better-overlapping views"
)


@dataclass(frozen=True)
class SfmOptions:
    camera_model: SfmCameraModel = "OPENCV"
    matching: MatchingMode = "auto"
    max_image_size: int = 1600
    ordered: bool = False  # frames of a video: sequential matching under "auto"
    verbose: bool = False
    seed: int = 0
    threads: int | None = None  # CPU threads of every stage; None: all cores


@dataclass(frozen=True)
class SfmOutcome:
    model_dir: Path  # colmap/sparse/0
    registered: list[str]
    unregistered: list[str]
    mean_reprojection_error: float
    matching: str
    point_count: int


def _database_counts(pycolmap: ModuleType, database: Path) -> tuple[int, int, int]:
    """(images, keypoints, verified image pairs) in the database."""
    db = pycolmap.Database.open(database)
    try:
        return db.num_images(), db.num_keypoints(), db.num_verified_image_pairs()
    finally:
        db.close()


def run_sfm(
    image_dir: Path, image_names: list[str], colmap_dir: Path, options: SfmOptions, display: StageDisplay
) -> SfmOutcome:
    """Run the stages on ``image_names`` (files in ``image_dir``), writing under ``colmap_dir``."""
    pycolmap = import_pycolmap(options.verbose)
    colmap_dir.mkdir(parents=True, exist_ok=True)
    database = colmap_dir / "database.db"
    database.unlink(missing_ok=True)  # features of an earlier run would be mixed in
    sizes = {image_size(image_dir / name) for name in image_names}
    n = len(image_names)

    with display.stage(f"extracting SIFT features of {n} photos", unit="photos") as stage:
        extract_features(
            pycolmap,
            database,
            image_dir,
            image_names,
            camera_model=options.camera_model,
            single_camera=len(sizes) == 1,
            max_image_size=options.max_image_size,
            threads=options.threads,
        )
        _, keypoints, _ = _database_counts(pycolmap, database)
        stage.detail = f"{keypoints / n:.0f} per photo"

    method = resolve_matching(options.matching, n, options.ordered)
    total_pairs = pair_count(method, n)
    with display.stage(f"matching features ({method}, {total_pairs} pairs)", unit="pairs") as stage:
        match_features(pycolmap, database, method, threads=options.threads, n_images=n)
        pairs = _database_counts(pycolmap, database)[2]
        stage.detail = f"{pairs} verified image pairs"
    if pairs == 0:
        fail(f"no two of the {n} photos in {image_dir} share enough matching features", OVERLAP_ADVICE)

    work_dir = colmap_dir / "models"
    shutil.rmtree(work_dir, ignore_errors=True)
    with display.stage("incremental mapping", total=n, unit="photos registered") as stage:
        result = run_incremental_mapping(
            pycolmap,
            database,
            image_dir,
            work_dir,
            image_names,
            on_registered=stage.advance,
            seed=options.seed,
            threads=options.threads,
        )
        if result is not None:
            stage.detail = f"{len(result.registered)} of {n} photos registered"
    shutil.rmtree(work_dir, ignore_errors=True)
    if result is None:
        fail(f"none of the {n} photos in {image_dir} could be registered (no model came out)", OVERLAP_ADVICE)

    model_dir = colmap_dir / "sparse" / "0"
    shutil.rmtree(model_dir, ignore_errors=True)
    model_dir.mkdir(parents=True)
    result.reconstruction.write(model_dir)
    return SfmOutcome(
        model_dir=model_dir,
        registered=result.registered,
        unregistered=result.unregistered,
        mean_reprojection_error=result.mean_reprojection_error,
        matching=method,
        point_count=int(result.reconstruction.num_points3D()),
    )
