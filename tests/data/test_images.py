"""Image loading (8/16-bit, gray, alpha, bad files) and premultiplied downscaling."""

from __future__ import annotations

import struct
import zlib
from pathlib import Path

import imageio.v3 as iio
import numpy as np
import pytest

from fourierf_plugin.data.images import downscale_rgba, load_image_rgba, load_images
from fourierf_plugin.utils.errors import UserError

_COLOUR_TYPE = {1: 0, 2: 4, 3: 2, 4: 6}


def _paeth(a: np.ndarray, b: np.ndarray, c: np.ndarray) -> np.ndarray:
    p = a + b - c
    pa, pb, pc = np.abs(p - a), np.abs(p - b), np.abs(p - c)
    return np.where((pa <= pb) & (pa <= pc), a, np.where(pb <= pc, b, c))


def write_png16(path: Path, arr: np.ndarray, filters: tuple[int, ...] = (0,)) -> None:
    """A 16-bit PNG writer (Pillow cannot write 16-bit colour); row y uses filter ``filters[y % len]``."""
    arr = np.asarray(arr, dtype=np.uint16)
    h, w = arr.shape[:2]
    c = 1 if arr.ndim == 2 else arr.shape[2]
    bpp = 2 * c
    raw = arr.astype(">u2").reshape(h, w * c).view(np.uint8).astype(np.int64)
    rows, prior = [], np.zeros(w * bpp, dtype=np.int64)
    for y in range(h):
        cur = raw[y]
        a = np.concatenate([np.zeros(bpp, dtype=np.int64), cur[:-bpp]])
        c_ = np.concatenate([np.zeros(bpp, dtype=np.int64), prior[:-bpp]])
        t = filters[y % len(filters)]
        pred = [np.zeros_like(cur), a, prior, (a + prior) >> 1, _paeth(a, prior, c_)][t]
        rows.append(bytes([t]) + ((cur - pred) & 0xFF).astype(np.uint8).tobytes())
        prior = cur

    def chunk(kind: bytes, body: bytes) -> bytes:
        return struct.pack(">I", len(body)) + kind + body + struct.pack(">I", zlib.crc32(kind + body))

    ihdr = struct.pack(">IIBBBBB", w, h, 16, _COLOUR_TYPE[c], 0, 0, 0)
    path.write_bytes(
        b"\x89PNG\r\n\x1a\n"
        + chunk(b"IHDR", ihdr)
        + chunk(b"IDAT", zlib.compress(b"".join(rows)))
        + chunk(b"IEND", b"")
    )


def test_rgba8_is_premultiplied(tmp_path: Path) -> None:
    img = np.zeros((4, 5, 4), dtype=np.uint8)
    img[1, 2] = (255, 0, 0, 128)
    img[0, 0] = (10, 20, 30, 255)
    iio.imwrite(tmp_path / "a.png", img)
    out = load_image_rgba(tmp_path / "a.png")
    assert out.shape == (4, 5, 4) and out.dtype == np.float32
    a = 128 / 255
    np.testing.assert_allclose(out[1, 2], [a, 0, 0, a], atol=1e-6)
    np.testing.assert_allclose(out[0, 0], [10 / 255, 20 / 255, 30 / 255, 1], atol=1e-6)
    np.testing.assert_array_equal(out[3, 3], 0)  # transparent pixel: colour premultiplied away
    assert (out[..., :3] <= out[..., 3:] + 1e-7).all()


def test_rgb_without_alpha_is_opaque_and_gray_is_replicated(tmp_path: Path) -> None:
    rng = np.random.default_rng(0)
    rgb = rng.integers(0, 256, (6, 7, 3), dtype=np.uint8)
    gray = rng.integers(0, 256, (6, 7), dtype=np.uint8)
    gray_alpha = rng.integers(0, 256, (6, 7, 2), dtype=np.uint8)
    iio.imwrite(tmp_path / "rgb.png", rgb)
    iio.imwrite(tmp_path / "gray.png", gray)
    iio.imwrite(tmp_path / "ga.png", gray_alpha)

    out = load_image_rgba(tmp_path / "rgb.png")
    np.testing.assert_allclose(out[..., :3], rgb / 255, atol=1e-6)
    np.testing.assert_array_equal(out[..., 3], 1)

    out = load_image_rgba(tmp_path / "gray.png")
    for ch in range(3):
        np.testing.assert_allclose(out[..., ch], gray / 255, atol=1e-6)
    np.testing.assert_array_equal(out[..., 3], 1)

    out = load_image_rgba(tmp_path / "ga.png")
    alpha = gray_alpha[..., 1] / 255
    np.testing.assert_allclose(out[..., 3], alpha, atol=1e-6)
    np.testing.assert_allclose(out[..., 1], gray_alpha[..., 0] / 255 * alpha, atol=1e-6)


def test_jpeg_reads_as_opaque_rgb(tmp_path: Path) -> None:
    rgb = np.full((16, 16, 3), (200, 100, 50), dtype=np.uint8)
    iio.imwrite(tmp_path / "a.jpg", rgb, quality=95)
    out = load_image_rgba(tmp_path / "a.jpg")
    np.testing.assert_allclose(out[..., :3], rgb / 255, atol=4 / 255)
    np.testing.assert_array_equal(out[..., 3], 1)


@pytest.mark.parametrize("channels", [1, 2, 3, 4])
def test_png16_full_precision_every_filter(tmp_path: Path, channels: int) -> None:
    """All five PNG filters, odd sizes: the 16-bit reader must return the exact values (Pillow keeps 8 bits)."""
    rng = np.random.default_rng(channels)
    arr = rng.integers(0, 65536, (9, 7, channels) if channels > 1 else (9, 7), dtype=np.uint16)
    arr.flat[0] = 1  # a value the high byte alone would round to 0
    write_png16(tmp_path / "a.png", arr, filters=(0, 1, 2, 3, 4))
    out = load_image_rgba(tmp_path / "a.png")
    values = arr.astype(np.float64) / 65535
    values = values[..., None] if channels == 1 else values
    alpha = values[..., -1] if channels in (2, 4) else np.ones(arr.shape[:2])
    np.testing.assert_allclose(out[..., 3], alpha, atol=1e-7)
    np.testing.assert_allclose(out[..., 0], values[..., 0] * alpha, atol=1e-7)
    if channels >= 3:
        np.testing.assert_allclose(out[..., 2], values[..., 2] * alpha, atol=1e-7)


def test_png16_matches_png8(tmp_path: Path) -> None:
    rng = np.random.default_rng(1)
    arr16 = rng.integers(0, 65536, (8, 8, 4), dtype=np.uint16)
    arr8 = np.round(arr16 / 257).astype(np.uint8)
    write_png16(tmp_path / "a16.png", arr16, filters=(4, 1))
    iio.imwrite(tmp_path / "a8.png", arr8)
    diff = np.abs(load_image_rgba(tmp_path / "a16.png") - load_image_rgba(tmp_path / "a8.png"))
    assert diff.max() <= 1 / 255


def test_bad_files_raise_user_error_naming_them(tmp_path: Path) -> None:
    (tmp_path / "junk.png").write_bytes(b"not an image at all")
    iio.imwrite(tmp_path / "float.tif", np.zeros((4, 4), dtype=np.float32))
    iio.imwrite(tmp_path / "five.tif", np.zeros((4, 4, 5), dtype=np.uint8))
    write_png16(tmp_path / "trunc.png", np.random.default_rng(0).integers(0, 65536, (8, 8, 4), dtype=np.uint16))
    (tmp_path / "trunc.png").write_bytes((tmp_path / "trunc.png").read_bytes()[:200])
    for name in ("junk.png", "float.tif", "five.tif", "trunc.png"):
        with pytest.raises(UserError) as info:
            load_image_rgba(tmp_path / name)
        assert name in info.value.problem and info.value.fix


def test_missing_file_names_path_and_referrer(tmp_path: Path) -> None:
    with pytest.raises(UserError) as info:
        load_image_rgba(tmp_path / "nope.png", referenced_by=tmp_path / "transforms_train.json")
    assert "nope.png" in info.value.problem and "transforms_train.json" in info.value.problem


def test_downscale_block_average_is_exact_and_commutes_with_compositing() -> None:
    rng = np.random.default_rng(0)
    alpha = rng.random((8, 12, 1)).astype(np.float32)
    img = np.concatenate([rng.random((8, 12, 3)).astype(np.float32) * alpha, alpha], axis=-1)
    assert downscale_rgba(img, 1) is img
    small = downscale_rgba(img, 4)
    assert small.shape == (2, 3, 4) and small.dtype == np.float32
    np.testing.assert_allclose(small[1, 2], img[4:8, 8:12].mean(axis=(0, 1)), atol=1e-6)
    # Compositing on white after downscaling equals downscaling the composited image.
    on_white = img[..., :3] + 1 - img[..., 3:]
    np.testing.assert_allclose(small[..., :3] + 1 - small[..., 3:], downscale_rgba(on_white, 4), atol=1e-6)


def test_downscale_non_divisible_and_invalid() -> None:
    img = np.full((10, 7, 4), 0.25, dtype=np.float32)
    out = downscale_rgba(img, 3)
    assert out.shape == (3, 2, 4) and out.dtype == np.float32
    np.testing.assert_allclose(out, 0.25, atol=1e-6)
    with pytest.raises(ValueError):
        downscale_rgba(img, 0)


def test_load_images_stacks_and_rejects_mixed_sizes(tmp_path: Path) -> None:
    paths = []
    for i in range(3):
        paths.append(tmp_path / f"r_{i}.png")
        iio.imwrite(paths[-1], np.full((8, 8, 4), 40 * i, dtype=np.uint8))
    out = load_images(paths, 2)
    assert out.shape == (3, 4, 4, 4)
    np.testing.assert_allclose(out[2, ..., 3], 80 / 255, atol=1e-6)

    iio.imwrite(tmp_path / "r_1.png", np.zeros((8, 6, 4), dtype=np.uint8))
    with pytest.raises(UserError) as info:
        load_images(paths, 1, referenced_by=tmp_path / "transforms_test.json")
    assert "r_1.png" in info.value.problem and "6x8" in info.value.problem and "8x8" in info.value.problem

    with pytest.raises(UserError, match="larger than the 8x8 image"):
        load_images(paths[:1], 9)


def test_load_images_reports_first_missing_file(tmp_path: Path) -> None:
    iio.imwrite(tmp_path / "r_0.png", np.zeros((4, 4, 4), dtype=np.uint8))
    paths = [tmp_path / "r_0.png", tmp_path / "r_1.png", tmp_path / "r_2.png"]
    with pytest.raises(UserError) as info:
        load_images(paths, 1)
    assert "r_1.png" in info.value.problem
