"""Colormaps of renders: float images to uint8, depth to colour (near to far along the map), accumulation to grey."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from fourierf_plugin.utils.colormaps import apply_colormap, colorize_accumulation, colorize_depth, to_uint8

LUMA = np.array([0.2126, 0.7152, 0.0722])


def test_to_uint8_rounds_clips_and_zeroes_nan() -> None:
    image = torch.tensor([0.0, 0.5, 1.0, -0.3, 1.7, float("nan")])
    assert to_uint8(image).tolist() == [0, 128, 255, 0, 255, 0]
    assert to_uint8(np.zeros((2, 3, 3))).dtype == np.uint8


def test_viridis_gets_lighter_with_depth_and_turbo_changes_colour() -> None:
    ramp = np.linspace(0.0, 1.0, 256)
    luma = apply_colormap(ramp, "viridis") @ LUMA
    assert np.all(np.diff(luma) > 0), "viridis is monotone in lightness"
    turbo = apply_colormap(ramp, "turbo")
    assert turbo.shape == (256, 3) and turbo.min() >= 0 and turbo.max() <= 1
    assert np.abs(np.diff(turbo, axis=0)).sum(axis=1).min() > 0, "neighbouring depths get different colours"


def test_colorize_depth_maps_near_and_far_to_the_ends_of_the_colormap() -> None:
    depth = torch.linspace(2.0, 6.0, 40).reshape(5, 8)
    image = colorize_depth(depth, near=2.0, far=6.0, cmap="viridis")
    assert image.shape == (5, 8, 3) and image.dtype == np.uint8
    assert np.array_equal(image[0, 0], to_uint8(apply_colormap(np.array(0.0), "viridis")))
    assert np.array_equal(image[-1, -1], to_uint8(apply_colormap(np.array(1.0), "viridis")))
    luma = image.reshape(-1, 3).astype(float) @ LUMA
    assert np.all(np.diff(luma) >= 0) and luma[-1] > luma[0] + 100, "farther is lighter, monotonically"
    auto = colorize_depth(depth, cmap="turbo")  # percentile range: the ends still differ
    assert not np.array_equal(auto[0, 0], auto[-1, -1])


def test_colorize_depth_paints_empty_pixels_and_survives_constant_depth() -> None:
    depth = torch.full((4, 4), 3.0)
    acc = torch.ones(4, 4)
    acc[0] = 0.0
    for background, value in (("white", 255), ("black", 0)):
        image = colorize_depth(depth, acc, background=background)
        assert (image[0] == value).all()
        assert len({tuple(p) for p in image[1:].reshape(-1, 3)}) == 1, "a constant depth is one colour"
    empty = colorize_depth(torch.zeros(3, 3), torch.zeros(3, 3))
    assert empty.shape == (3, 3, 3)
    nan = colorize_depth(torch.tensor([[float("nan"), 1.0], [2.0, 3.0]]))
    assert nan.dtype == np.uint8
    with pytest.raises(ValueError, match=r"\[H, W\]"):
        colorize_depth(torch.zeros(2, 2, 1))


def test_colorize_accumulation_is_grey() -> None:
    image = colorize_accumulation(torch.tensor([[0.0, 1.0]]))
    assert image.shape == (1, 2, 3) and image.tolist() == [[[0, 0, 0], [255, 255, 255]]]
