"""Input photos: which files count, the minimum count, and the downscaled folders."""

from __future__ import annotations

from pathlib import Path

import imageio.v3 as iio
import numpy as np
import pytest

from fourierf_plugin.sfm.photos import check_photo_count, copy_photos, list_photos, write_downscaled
from fourierf_plugin.utils.errors import UserError


def test_list_photos_keeps_images_in_natural_order(tmp_path: Path) -> None:
    for name in ("IMG_10.JPG", "IMG_2.jpg", "img_3.png", "notes.txt", "IMG_1.jpeg"):
        (tmp_path / name).write_bytes(b"x")
    (tmp_path / "sub.png").mkdir()
    assert [p.name for p in list_photos(tmp_path)] == ["IMG_1.jpeg", "IMG_2.jpg", "img_3.png", "IMG_10.JPG"]
    with pytest.raises(UserError, match="photo folder not found"):
        list_photos(tmp_path / "missing")


def test_fewer_than_three_photos_is_a_clear_error(tmp_path: Path) -> None:
    photos = [tmp_path / "a.jpg", tmp_path / "b.jpg"]
    with pytest.raises(UserError, match=r"holds 2 photo\(s\) .*found: a.jpg, b.jpg.*at least 3") as info:
        check_photo_count(photos, tmp_path)
    assert "overlap" in info.value.fix
    check_photo_count([*photos, tmp_path / "c.jpg"], tmp_path)


def test_downscaled_folders_hold_block_averages_under_the_same_names(tmp_path: Path) -> None:
    rng = np.random.default_rng(0)
    rgb = rng.integers(0, 256, (48, 64, 3)).astype(np.uint8)
    rgba = np.concatenate([rgb, np.full((48, 64, 1), 255, np.uint8)], axis=2)
    rgba[:, :32, 3] = 0  # left half transparent: its colour must not bleed
    rgba[:, 32:, :3] = 200
    source = tmp_path / "src"
    source.mkdir()
    iio.imwrite(source / "a.png", rgb)
    iio.imwrite(source / "b.png", rgba)
    iio.imwrite(source / "c.jpg", rgb, quality=95)
    images = tmp_path / "scene" / "images"
    copies = copy_photos(sorted(source.iterdir()), images)
    assert [p.name for p in copies] == ["a.png", "b.png", "c.jpg"]
    folders = write_downscaled(images, copies)
    assert [f.name for f in folders] == ["images_2", "images_4", "images_8"]
    for factor, folder in zip((2, 4, 8), folders, strict=True):
        assert sorted(p.name for p in folder.iterdir()) == ["a.png", "b.png", "c.jpg"]
        small = iio.imread(folder / "a.png")
        assert small.shape == (48 // factor, 64 // factor, 3)
        expected = rgb.reshape(48 // factor, factor, 64 // factor, factor, 3).mean(axis=(1, 3))
        assert np.abs(small.astype(float) - expected).max() <= 0.5 + 1e-9
        alpha_small = iio.imread(folder / "b.png")
        assert alpha_small.shape == (48 // factor, 64 // factor, 4)
        opaque = alpha_small[:, alpha_small.shape[1] // 2 :]
        assert (opaque[..., :3] == 200).all() and (opaque[..., 3] == 255).all()
        assert (alpha_small[:, : alpha_small.shape[1] // 2, 3] == 0).all()
        assert iio.imread(folder / "c.jpg").shape == (48 // factor, 64 // factor, 3)
