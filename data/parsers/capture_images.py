"""The photos of a capture at one resolution: nerfstudio's downscaled folders, one size for every image, masks as alpha.

nerfstudio keeps downscaled copies beside the originals (``images/x.png`` -> ``images_4/x.png``); a factor with no
folder is made from the highest-resolution copy whose factor divides it. Every image of a scene ends at one size
(``Cameras`` holds one width and height): photos of another size but the same aspect ratio are resized, and their
intrinsics scaled by the caller, which only needs the target size.
"""

from __future__ import annotations

import os
from collections.abc import Sequence
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import numpy as np

from fourierf_plugin.data.capture import Frame
from fourierf_plugin.data.images import downscale_rgba, load_image_rgba
from fourierf_plugin.utils.errors import fail

MAX_AUTO_SIDE = 1600
"""Without --downscale, the smallest power-of-two factor that brings the longer side to at most this (nerfstudio's
rule)."""
_PER_FRAME_FIX = (
    "give each frame of a different size its own w, h, fl_x, fl_y, cx, cy in transforms.json, "
    "or resize the photos to the size the file gives"
)


def variant_path(path: Path, factor: int) -> Path:
    """Where nerfstudio keeps ``path`` downscaled by ``factor``: ``<folder>_<factor>/<name>`` beside its folder."""
    return path if factor == 1 else path.parent.parent / f"{path.parent.name}_{factor}" / path.name


def variants(path: Path) -> dict[int, Path]:
    """The copies of ``path`` present on disk, by downscale factor (1: the file itself)."""
    found = {1: path} if path.is_file() else {}
    folder = path.parent
    prefix = f"{folder.name}_"
    if folder.parent.is_dir():
        for sibling in folder.parent.iterdir():
            suffix = sibling.name[len(prefix) :] if sibling.name.startswith(prefix) else ""
            if suffix.isdigit() and int(suffix) > 1 and (sibling / path.name).is_file():
                found[int(suffix)] = sibling / path.name
    return dict(sorted(found.items()))


def pick_variant(path: Path, downscale: int, referenced_by: Path) -> tuple[Path, int]:
    """The file to read for ``downscale`` and the integer factor still to apply to it: ``<folder>_<downscale>`` when
    present, else the highest-resolution copy whose factor divides ``downscale`` (as the LLFF parser picks)."""
    present = variants(path)
    if downscale in present:
        return present[downscale], 1
    usable = [k for k in present if downscale % k == 0]
    if not usable:
        if not present:
            fail(
                f"image not found: {path} (referenced by {referenced_by})",
                f"restore it or fix its entry in {referenced_by}",
            )
        fail(
            f"no copy of {path} to read at --downscale {downscale} (found factors {sorted(present)}; "
            f"referenced by {referenced_by})",
            f"add {variant_path(path, downscale)}, or pick a --downscale that one of {sorted(present)} divides",
        )
    k = min(usable)
    return present[k], downscale // k


def auto_downscale(width: int, height: int, max_side: int = MAX_AUTO_SIDE) -> int:
    """The smallest power of two that brings the longer side to at most ``max_side``."""
    factor = 1
    while max(width, height) / factor > max_side:
        factor *= 2
    return factor


def most_common_size(frames: Sequence[Frame]) -> tuple[int, int]:
    """The (width, height) most frames have (the first one seen on a tie): the size every image is brought to."""
    sizes = [(f.intrinsics.width, f.intrinsics.height) for f in frames]
    return max(dict.fromkeys(sizes), key=sizes.count)


def _same_aspect(width: int, height: int, other_width: int, other_height: int) -> bool:
    """Whether ``width x height`` is ``other`` scaled, allowing the 1 px a downscaled copy may round by."""
    return abs(height - width * other_height / other_width) <= 1.0 + 0.005 * height


def target_size(frames: Sequence[Frame], downscale: int, referenced_by: Path) -> tuple[int, int]:
    """(width, height) every loaded image gets: the most common full size read at ``downscale``.

    Read from one file rather than computed, so a downscaled copy that rounded its size is used as is.
    """
    full = most_common_size(frames)
    frame = next(f for f in frames if (f.intrinsics.width, f.intrinsics.height) == full)
    path, extra = pick_variant(frame.image_path, downscale, referenced_by)
    height, width = load_image_rgba(path, referenced_by).shape[:2]
    _check_file_size(frame, path, downscale // extra, (width, height), referenced_by)
    if min(width, height) < extra:
        fail(
            f"--downscale {downscale} is larger than the {width}x{height} image {path}",
            f"use a --downscale of at most {min(full)}",
        )
    return width // extra, height // extra


def _shrink(img: np.ndarray, factor: int, path: Path, width: int, height: int) -> np.ndarray:
    """``img`` (read from ``path``) downscaled by ``factor`` (exact block means when it divides), then resized to
    ``width x height`` if it is not that size yet."""
    if factor > min(img.shape[:2]):
        fail(
            f"the downscale factor {factor} is larger than the {img.shape[1]}x{img.shape[0]} image {path}",
            "use a smaller --downscale",
        )
    img = downscale_rgba(img, factor)
    if img.shape[:2] == (height, width):
        return img
    from skimage.transform import resize  # imported lazily: skimage is slow to import and rarely needed here

    out = resize(img, (height, width, img.shape[2]), order=1, anti_aliasing=True, preserve_range=True)
    return np.clip(out, 0.0, 1.0).astype(np.float32)


def _check_file_size(frame: Frame, path: Path, factor: int, size: tuple[int, int], referenced_by: Path) -> None:
    """The file must be its frame's w x h (a ``_k`` copy: w/k x h/k, within the 1 px rounding of a resize)."""
    width, height = size
    want_w, want_h = frame.intrinsics.width / factor, frame.intrinsics.height / factor
    if abs(width - want_w) > 1 or abs(height - want_h) > 1:
        fail(
            f"image {path} is {width}x{height}, but {referenced_by} gives its frame ({frame.image_path.name}) "
            f"w x h = {frame.intrinsics.width}x{frame.intrinsics.height}"
            + (f" (so {want_w:g}x{want_h:g} in a copy downscaled by {factor})" if factor > 1 else ""),
            _PER_FRAME_FIX,
        )


def _load_one(frame: Frame, downscale: int, target: tuple[int, int], referenced_by: Path) -> np.ndarray:
    """One frame as premultiplied RGBA at ``target``; its mask (if any) multiplies all four channels."""
    width, height = target
    path, extra = pick_variant(frame.image_path, downscale, referenced_by)
    img = load_image_rgba(path, referenced_by)
    _check_file_size(frame, path, downscale // extra, (img.shape[1], img.shape[0]), referenced_by)
    full_w, full_h = frame.intrinsics.width, frame.intrinsics.height
    if not _same_aspect(full_w, full_h, width, height):
        fail(
            f"{frame.image_path} is {full_w}x{full_h}, but most photos of {referenced_by} are {width}x{height} at "
            "this scale: their aspect ratios differ, and one scene needs one image size",
            "crop or resize the photos to one aspect ratio (and update their w, h, fl_x, fl_y, cx, cy)",
        )
    img = _shrink(img, extra, path, width, height)
    if frame.mask_path is not None:
        mask_path, mask_extra = pick_variant(frame.mask_path, downscale, referenced_by)
        mask = load_image_rgba(mask_path, referenced_by)[:, :, :1]  # gray: 0 drops a pixel, 1 keeps it
        if not _same_aspect(mask.shape[1], mask.shape[0], width, height):
            fail(
                f"mask {mask_path} is {mask.shape[1]}x{mask.shape[0]}, not the shape of its image {path}",
                f"write the mask at the image's size, or fix mask_path in {referenced_by}",
            )
        img = img * _shrink(mask, mask_extra, mask_path, width, height)
    return img


def load_frames(frames: Sequence[Frame], downscale: int, target: tuple[int, int], referenced_by: Path) -> np.ndarray:
    """Premultiplied RGBA [N, H, W, 4] float32 of ``frames`` at ``target`` (width, height), decoded on a few threads;
    errors come in frame order."""
    width, height = target
    out = np.empty((len(frames), height, width, 4), dtype=np.float32)
    workers = max(1, min(4, os.cpu_count() or 1, len(frames)))
    with ThreadPoolExecutor(max_workers=workers) as pool:
        for i, img in enumerate(pool.map(lambda f: _load_one(f, downscale, target, referenced_by), frames)):
            out[i] = img
    return out


def has_alpha(path: Path) -> bool:
    """Whether an image file carries an alpha channel, from its first bytes (PNG gray+alpha or RGBA); other formats
    (JPEG photos) have none."""
    try:
        with open(path, "rb") as fh:
            head = fh.read(26)
    except OSError:
        return False
    return head.startswith(b"\x89PNG\r\n\x1a\n") and head[12:16] == b"IHDR" and head[25] in (4, 6)
