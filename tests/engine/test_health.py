"""A run that learnt nothing is told apart from a healthy one: an empty field, or renders worse than a flat colour."""

from __future__ import annotations

import math

import pytest
import torch

from fourierf_plugin.engine.health import MIN_ITERATIONS_TO_JUDGE, dead_field_problem, flat_colour_psnr


def test_flat_colour_psnr_is_the_variance_of_the_images() -> None:
    images = torch.zeros(2, 4, 4, 4)
    images[..., 3] = 1.0
    images[0, ..., :3] = 0.25
    images[1, ..., :3] = 0.75  # variance 1/16 in every channel
    assert flat_colour_psnr(images) == pytest.approx(-10 * math.log10(1 / 16))
    transparent = torch.zeros(1, 2, 2, 4)  # composited on white: one flat colour
    assert flat_colour_psnr(transparent) == pytest.approx(100.0)


def test_an_empty_or_flat_field_is_dead_and_a_lit_one_or_a_short_run_is_not() -> None:
    long = MIN_ITERATIONS_TO_JUDGE
    assert "empty" in str(dead_field_problem(long, True, 25.0, 12.0))
    assert "flat colour" in str(dead_field_problem(long, False, 5.0, 12.0))
    assert dead_field_problem(long, False, 20.0, 12.0) is None
    assert dead_field_problem(long, False, None, 12.0) is None
    assert dead_field_problem(long - 1, True, 5.0, 12.0) is None  # too short to judge
