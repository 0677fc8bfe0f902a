"""Whether a finished run learnt anything: a field that stayed empty, or renders no better than one flat colour,
ends the run with a clear message instead of a success line."""

from __future__ import annotations

import math

from torch import Tensor

MIN_ITERATIONS_TO_JUDGE = 200
"""Shorter runs (tests, smoke runs) may not have lit their field yet: they are not judged."""


def flat_colour_psnr(images: Tensor) -> float:
    """PSNR of the best single colour (each channel's mean) against RGBA images [N, H, W, 4] composited on white:
    what a field that learnt nothing but a colour would score."""
    rgb = images[..., :3].float() + (1.0 - images[..., 3:4].float())
    variance = rgb.reshape(-1, 3).var(dim=0, unbiased=False).mean().item()
    return -10.0 * math.log10(max(variance, 1e-10))


def dead_field_problem(iterations: int, empty_grid: bool, train_psnr: float | None, flat_psnr: float) -> str | None:
    """What says the run learnt nothing, or None for a healthy (or too short to judge) run."""
    if iterations < MIN_ITERATIONS_TO_JUDGE:
        return None
    if empty_grid:
        return "the density field is empty: its last occupancy update found no grid vertex above the threshold"
    if train_psnr is not None and train_psnr < flat_psnr:
        return (
            f"the training views render at {train_psnr:.1f} dB, below the {flat_psnr:.1f} dB of one flat colour: "
            "the field learnt nothing"
        )
    return None


DEAD_FIELD_FIX = (
    "check that the cameras look into the scene box (fourierf-render dataset --load-config RUN/config.json shows what "
    "the run sees); for photos of an object with its surroundings pass --scene-kind unbounded after the dataparser; "
    "or try another --seed, or a lower --pipeline.model.occupancy-threshold"
)
