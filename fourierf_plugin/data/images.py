"""Image files to premultiplied float RGBA, and resizing that keeps compositing exact.

Colour is premultiplied by alpha as soon as it is read: averaging premultiplied values is the same as averaging
the composited images, so downscaling never bleeds the (arbitrary) colour of transparent pixels into edges.
"""

from __future__ import annotations

import os
import struct
import zlib
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import imageio.v3 as iio
import numpy as np

from fourierf_plugin.utils.errors import UserError, fail
from fourierf_plugin.utils.memory import check_fits

_PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"
_PNG_CHANNELS = {0: 1, 2: 3, 4: 2, 6: 4}  # PNG colour type -> channels (gray, RGB, gray+alpha, RGBA)
# Pillow modes that hold colour in another space; read them converted to RGB.
_CONVERT_TO_RGB = {"CMYK", "YCbCr", "LAB", "HSV"}
_SAVE_FIX = "re-save it as an 8- or 16-bit PNG (RGB, RGBA, gray or gray+alpha)"


def _where(path: Path, referenced_by: Path | None) -> str:
    return f"{path}" if referenced_by is None else f"{path} (referenced by {referenced_by})"


def _sniff(path: Path) -> tuple[str, int]:
    """("png", bit depth), ("jpeg", 8) or ("other", 0) from the file's first bytes."""
    with open(path, "rb") as fh:
        head = fh.read(33)
    if head.startswith(_PNG_SIGNATURE) and len(head) == 33 and head[12:16] == b"IHDR":
        return "png", head[24]
    if head.startswith(b"\xff\xd8\xff"):
        return "jpeg", 8
    return "other", 0


def _unfilter(filtered: np.ndarray, filter_types: np.ndarray) -> np.ndarray:
    """Undo PNG scanline filters: [H, W, bpp] filtered bytes -> [H, W, bpp] uint8.

    Sub, Average and Paeth depend on the reconstructed left neighbour, so no row vectorises; instead sweep
    anti-diagonals (y + x = k), whose pixels depend only on the two diagonals before them.
    """
    h, w, bpp = filtered.shape
    rec = np.zeros((h + 1, w + 1, bpp), dtype=np.int32)  # one row/column of zeros in front: the PNG edge rule
    filt = filtered.astype(np.int32)
    for k in range(h + w - 1):
        ys = np.arange(max(0, k - w + 1), min(h - 1, k) + 1)
        xs = k - ys
        a = rec[ys + 1, xs]  # left
        b = rec[ys, xs + 1]  # up
        c = rec[ys, xs]  # up-left
        p = a + b - c
        pa, pb, pc = np.abs(p - a), np.abs(p - b), np.abs(p - c)
        paeth = np.where((pa <= pb) & (pa <= pc), a, np.where(pb <= pc, b, c))
        t = filter_types[ys][:, None]
        pred = np.select([t == 1, t == 2, t == 3, t == 4], [a, b, (a + b) >> 1, paeth], 0)
        rec[ys + 1, xs + 1] = (filt[ys, xs] + pred) & 0xFF
    return rec[1:, 1:].astype(np.uint8)


DECODE_BYTES_PER_VALUE = 14
"""Peak bytes per 16-bit sample while ``_read_png16`` decodes: the inflated rows, two int32 working copies of
``_unfilter`` and its uint8 and uint16 results."""


def max_image_pixels() -> int | None:
    """The pixel count beyond which an image is refused as a decompression bomb: twice Pillow's warning limit (where
    Pillow itself raises), or None when the limit is switched off."""
    from PIL import Image

    limit = Image.MAX_IMAGE_PIXELS
    return None if limit is None else 2 * int(limit)


def check_decode_size(path: Path, width: int, height: int, channels: int) -> None:
    """A UserError, from the header's dimensions and before any pixel is inflated, for an image larger than the
    decompression-bomb limit or than the memory its decoding needs."""
    limit = max_image_pixels()
    if width < 1 or height < 1:
        fail(f"image {path} is corrupt (its header says {width}x{height} pixels)", _SAVE_FIX)
    if limit is not None and width * height > limit:
        fail(
            f"image {path} declares {width}x{height} pixels, over the {limit} pixels that may be decoded "
            "(a decompression bomb, or an image far larger than a scene needs)",
            "downscale the image before training",
        )
    check_fits(
        width * height * channels * DECODE_BYTES_PER_VALUE,
        f"decoding the {width}x{height} 16-bit image {path}",
        "downscale the image before training",
    )


def _read_png16(path: Path) -> np.ndarray:
    """Full-precision reader for 16-bit PNGs ([H, W] or [H, W, C] uint16).

    Pillow (behind imageio) keeps only the high byte of 16-bit colour PNGs; Blender can write 16-bit renders.
    """
    data = path.read_bytes()
    pos, idat, ihdr = len(_PNG_SIGNATURE), [], None
    while pos + 12 <= len(data):
        (length,) = struct.unpack(">I", data[pos : pos + 4])
        kind, body = data[pos + 4 : pos + 8], data[pos + 8 : pos + 8 + length]
        (crc,) = struct.unpack(">I", data[pos + 8 + length : pos + 12 + length] or b"\0\0\0\0")
        if len(body) != length or zlib.crc32(kind + body) != crc:
            fail(f"image {path} is corrupt (bad or truncated PNG chunk {kind!r})", _SAVE_FIX)
        if kind == b"IHDR":
            ihdr = struct.unpack(">IIBBBBB", body)
        elif kind == b"IDAT":
            idat.append(body)
        elif kind == b"IEND":
            break
        pos += 12 + length
    if ihdr is None or not idat:
        fail(f"image {path} is corrupt (PNG without IHDR or IDAT)", _SAVE_FIX)
    width, height, _depth, ctype, _, _, interlace = ihdr
    if interlace:
        fail(f"image {path} is an interlaced 16-bit PNG, which is not supported", "re-save it without interlacing")
    if ctype not in _PNG_CHANNELS:
        fail(f"image {path} has PNG colour type {ctype} at 16 bits, which is not supported", _SAVE_FIX)
    channels = _PNG_CHANNELS[ctype]
    check_decode_size(path, width, height, channels)
    stride = width * channels * 2
    try:  # never inflate past what the header's size needs: a small file may expand without end
        raw = np.frombuffer(zlib.decompressobj().decompress(b"".join(idat), height * (stride + 1)), dtype=np.uint8)
    except zlib.error as err:
        fail(f"image {path} is corrupt ({err})", _SAVE_FIX)
    if raw.size < height * (stride + 1):
        fail(f"image {path} is corrupt (pixel data is truncated)", _SAVE_FIX)
    rows = raw[: height * (stride + 1)].reshape(height, stride + 1)
    if rows[:, 0].max(initial=0) > 4:
        fail(f"image {path} is corrupt (unknown PNG filter type)", _SAVE_FIX)
    pixels = _unfilter(rows[:, 1:].reshape(height, width, channels * 2), rows[:, 0])
    out = pixels.reshape(height, width * channels * 2).view(">u2").astype(np.uint16)
    return out.reshape(height, width) if channels == 1 else out.reshape(height, width, channels)


def _read_pixels(path: Path) -> np.ndarray:
    kind, depth = _sniff(path)
    if kind == "png" and depth == 16:
        return _read_png16(path)
    if kind == "other" and path.suffix.lower() in (".tif", ".tiff"):  # Pillow misreads many-channel TIFFs
        return iio.imread(path, index=0, plugin="tifffile")
    with iio.imopen(path, "r", plugin="pillow") as image:
        mode = image.metadata(index=0).get("mode")
        return image.read(index=0, mode="RGB" if mode in _CONVERT_TO_RGB else None)


def load_image_rgba(path: Path, referenced_by: Path | None = None) -> np.ndarray:
    """Read an 8/16-bit image as float32 [H, W, 4] in [0, 1], colour premultiplied by alpha.

    Gray is replicated to RGB; images without alpha are opaque.
    """
    path = Path(path)
    where = _where(path, referenced_by)
    if not path.is_file():
        fix = "check the path" if referenced_by is None else f"restore the file or fix its entry in {referenced_by}"
        fail(f"image not found: {where}", fix)
    try:
        pixels = _read_pixels(path)
    except UserError:
        raise
    except Exception as err:  # any decoder failure on a user's file is a user-fixable problem
        fail(f"cannot read image {where}: {err}", f"check that the file is a valid PNG or JPEG, or {_SAVE_FIX}")
    scale = {np.dtype(np.uint8): 1 / 255, np.dtype(np.uint16): 1 / 65535, np.dtype(np.bool_): 1.0}.get(pixels.dtype)
    if scale is None:
        fail(f"image {where} has {pixels.dtype} pixels; only 8- and 16-bit integer images are supported", _SAVE_FIX)
    if pixels.ndim == 2:
        pixels = pixels[:, :, None]
    if pixels.ndim != 3 or pixels.shape[2] not in (1, 2, 3, 4):
        fail(f"image {where} has shape {pixels.shape}; expected gray, gray+alpha, RGB or RGBA", _SAVE_FIX)
    channels = pixels.shape[2]
    out = np.empty((*pixels.shape[:2], 4), dtype=np.float32)  # one allocation: this runs for every image
    out[:, :, :3] = pixels[:, :, :1] if channels in (1, 2) else pixels[:, :, :3]
    out[:, :, 3] = pixels[:, :, -1] if channels in (2, 4) else 1 / scale
    out *= np.float32(scale)
    out[:, :, :3] *= out[:, :, 3:]
    return out


def downscale_rgba(img: np.ndarray, factor: int) -> np.ndarray:
    """Shrink [H, W, C] premultiplied RGBA by an integer factor.

    Exact block averages when the size divides; otherwise an anti-aliased resize to (H // factor, W // factor).
    """
    if factor < 1:
        raise ValueError(f"downscale factor must be >= 1, got {factor}")
    if factor == 1:
        return img
    h, w, c = img.shape
    if h % factor == 0 and w % factor == 0:
        blocks = img.reshape(h // factor, factor, w // factor, factor, c)
        return blocks.mean(axis=(1, 3), dtype=np.float32)
    from skimage.transform import resize  # imported lazily: skimage is slow to import and rarely needed here

    out = resize(img, (h // factor, w // factor, c), order=1, anti_aliasing=True, preserve_range=True)
    return np.clip(out, 0.0, 1.0).astype(np.float32)


def _load_small(path: Path, downscale: int, referenced_by: Path | None) -> tuple[tuple[int, int], np.ndarray | None]:
    """Original (W, H) and the downscaled image (None when the factor exceeds the image)."""
    img = load_image_rgba(Path(path), referenced_by)
    size = (img.shape[1], img.shape[0])
    return size, (downscale_rgba(img, downscale) if downscale <= min(size) else None)


def load_images(paths: list[Path], downscale: int, referenced_by: Path | None = None) -> np.ndarray:
    """Load same-sized images as float32 [N, H // downscale, W // downscale, 4] premultiplied RGBA.

    Decoding runs on a few threads (the decoders release the GIL); errors still come in file order.
    """
    if downscale < 1:
        raise ValueError(f"downscale factor must be >= 1, got {downscale}")
    if not paths:
        raise ValueError("load_images needs at least one path")
    out: np.ndarray | None = None
    first_size = (0, 0)
    workers = min(4, os.cpu_count() or 1, len(paths))
    with ThreadPoolExecutor(max_workers=workers) as pool:
        results = pool.map(lambda p: _load_small(p, downscale, referenced_by), paths)
        for i, (path, (size, small)) in enumerate(zip(paths, results, strict=True)):
            if out is None:
                first_size = size
                if small is None:
                    fail(
                        f"downscale factor {downscale} is larger than the {size[0]}x{size[1]} image "
                        f"{_where(path, referenced_by)}",
                        f"use a downscale factor of at most {min(size)}",
                    )
                out = np.empty((len(paths), *small.shape), dtype=np.float32)
            elif size != first_size:
                fail(
                    f"image {_where(path, referenced_by)} is {size[0]}x{size[1]} but {paths[0]} is "
                    f"{first_size[0]}x{first_size[1]}; all images of a scene must have the same size",
                    "resize the images to one size (or regenerate the scene)",
                )
            out[i] = small
    assert out is not None
    return out
