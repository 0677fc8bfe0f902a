"""Incremental mapping (COLMAP's mapper): poses and sparse points from the verified matches; the largest model."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from types import ModuleType
from typing import Any


@dataclass(frozen=True)
class MappingResult:
    """The kept (largest) reconstruction and how it went."""

    reconstruction: Any  # pycolmap.Reconstruction
    registered: list[str]  # image names with a pose, in the input order
    unregistered: list[str]  # input image names without one
    mean_reprojection_error: float  # pixels
    models_found: int


def run_incremental_mapping(
    pycolmap: ModuleType,
    database: Path,
    image_dir: Path,
    work_dir: Path,
    image_names: list[str],
    on_registered: Callable[[int], None] | None = None,
    seed: int = 0,
    threads: int | None = None,
) -> MappingResult | None:
    """Map; None when no model came out (nothing could be registered).

    Small sets keep models down to 3 images (COLMAP's default minimum of 10 would discard a 6-photo capture);
    ``on_registered(k)`` is called as images are registered (k new ones at a time); ``threads``: CPU threads of the
    mapper and its bundle adjustments (None: all cores).
    """
    pycolmap.set_random_seed(seed)
    options = pycolmap.IncrementalPipelineOptions()
    options.min_model_size = min(options.min_model_size, max(3, len(image_names) // 2))
    options.random_seed = seed
    if threads is not None:
        options.num_threads = threads
    callbacks: dict[str, Callable[[], None]] = {}
    if on_registered is not None:
        callbacks = {
            "initial_image_pair_callback": lambda: on_registered(2),
            "next_image_callback": lambda: on_registered(1),
        }
    work_dir.mkdir(parents=True, exist_ok=True)
    models = pycolmap.incremental_mapping(database, image_dir, work_dir, options=options, **callbacks)
    if not models:
        return None
    largest = max(models.values(), key=lambda rec: rec.num_reg_images())
    if largest.num_reg_images() == 0:
        return None
    posed = {image.name for image in largest.images.values() if image.has_pose}
    return MappingResult(
        reconstruction=largest,
        registered=[name for name in image_names if name in posed],
        unregistered=[name for name in image_names if name not in posed],
        mean_reprojection_error=float(largest.compute_mean_reprojection_error()),
        models_found=len(models),
    )
