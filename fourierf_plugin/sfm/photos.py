"""The input photos: which files count, copies into the scene folder, and the downscaled folders beside them.

Why copies: the scene folder is then self-contained (``transforms.json`` points into it) and the user's originals are
never written to. Why ``images_2/4/8``: nerfstudio's parsers read ``images_<k>/`` for a downscale factor k, and
few-shot training runs on small images.
"""

from __future__ import annotations

import re
import shutil
from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import imageio.v3 as iio
import numpy as np

from fourierf_plugin.data.images import downscale_rgba
from fourierf_plugin.utils.errors import fail

PHOTO_SUFFIXES = (".jpg", ".jpeg", ".png")
MIN_PHOTOS = 3
DOWNSCALE_FACTORS = (2, 4, 8)


def _natural_key(path: Path) -> list:
    return [int(tok) if tok.isdigit() else tok.lower() for tok in re.split(r"(\d+)", path.name)]


def list_photos(folder: Path) -> list[Path]:
    """The photos directly in ``folder`` (.jpg, .jpeg, .png in any case), in natural name order."""
    folder = Path(folder)
    if not folder.is_dir():
        fail(f"photo folder not found: {folder}", "pass --data pointing at a folder of .jpg or .png photos")
    return sorted((p for p in folder.iterdir() if p.is_file() and p.suffix.lower() in PHOTO_SUFFIXES), key=_natural_key)


def check_photo_count(photos: list[Path], where: Path) -> None:
    """Structure-from-motion needs a few overlapping views; fewer than three cannot give a usable scene."""
    if len(photos) < MIN_PHOTOS:
        found = ", ".join(p.name for p in photos) or "none"
        fail(
            f"{where} holds {len(photos)} photo(s) (.jpg, .jpeg or .png; found: {found}); structure-from-motion "
            f"needs at least {MIN_PHOTOS}",
            "add more photos of the scene, taken from nearby viewpoints with plenty of overlap (20-100 is typical)",
        )


def image_size(path: Path) -> tuple[int, int]:
    """(width, height) of an image file, read from its header when the format allows."""
    try:
        shape = iio.improps(path).shape
    except Exception as err:  # any decoder failure on a user's file is a user-fixable problem
        fail(f"cannot read image {path} ({err})", "remove the file from the folder, or re-save it as PNG or JPEG")
    return int(shape[1]), int(shape[0])


def copy_photos(photos: list[Path], destination: Path, on_copied: Callable[[int], None] | None = None) -> list[Path]:
    """Copy the photos into ``destination`` under their own names; returns the copies. ``on_copied(1)`` after each."""
    destination.mkdir(parents=True, exist_ok=True)
    copies = []
    for photo in photos:
        target = destination / photo.name
        shutil.copyfile(photo, target)
        copies.append(target)
        if on_copied is not None:
            on_copied(1)
    return copies


def downscale_photo(path: Path, target: Path, factor: int) -> None:
    """Shrink one photo by an integer factor (area averaging; alpha kept) and save it in the same format."""
    pixels = iio.imread(path)
    dtype = pixels.dtype
    scale = float(np.iinfo(dtype).max) if np.issubdtype(dtype, np.integer) else 1.0
    img = pixels.astype(np.float32) / scale
    if img.ndim == 2:
        img = img[:, :, None]
    if img.shape[2] in (2, 4):  # average premultiplied colour, so transparent pixels do not bleed into edges
        img[:, :, :-1] *= img[:, :, -1:]
    small = downscale_rgba(img, factor)
    if small.shape[2] in (2, 4):
        alpha = small[:, :, -1:]
        small[:, :, :-1] = np.where(alpha > 0, small[:, :, :-1] / np.maximum(alpha, 1e-8), 0.0)
    out = np.clip(np.rint(small * scale), 0, scale).astype(dtype)
    out = out[:, :, 0] if out.shape[2] == 1 else out
    extra = {"quality": 95} if target.suffix.lower() in (".jpg", ".jpeg") else {}
    iio.imwrite(target, out, **extra)


def write_downscaled(
    images_dir: Path,
    photos: list[Path],
    factors: tuple[int, ...] = DOWNSCALE_FACTORS,
    threads: int | None = None,
    on_photo: Callable[[int], None] | None = None,
) -> list[Path]:
    """``images_<k>/`` beside ``images_dir`` for each factor k, with the same file names; returns the folders.

    Factors that would shrink the smallest photo below one pixel are left out. Photos are shrunk on ``threads``
    threads (None: one), decoding and encoding release the GIL; ``on_photo(1)`` after each photo's copies."""
    smallest = min(min(image_size(photo)) for photo in photos)
    folders = [images_dir.parent / f"{images_dir.name}_{k}" for k in factors if k <= smallest]
    for folder in folders:
        folder.mkdir(parents=True, exist_ok=True)

    def shrink(photo: Path) -> None:
        for folder in folders:
            downscale_photo(photo, folder / photo.name, int(folder.name.rsplit("_", 1)[1]))
        if on_photo is not None:
            on_photo(1)

    with ThreadPoolExecutor(max_workers=max(1, threads or 1)) as pool:
        list(pool.map(shrink, photos))  # list(): an error in any photo is raised here
    return folders
