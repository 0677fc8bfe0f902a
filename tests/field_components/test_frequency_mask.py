"""FreeNeRF's frequency mask and masked positional encoding against hand-computed values."""

from __future__ import annotations

import math

import pytest
import torch

from fourierf_plugin.field_components.frequency_mask import band_mask, encode, encoded_width, visible_share


def test_the_visible_share_ramps_from_zero_to_one_and_stays() -> None:
    assert [visible_share(t, 90) for t in (0, 30, 45, 90, 120)] == pytest.approx([0.0, 1 / 3, 0.5, 1.0, 1.0])
    assert visible_share(0, 0) == 1.0, "no ramp: every band from the start"


def test_the_edge_band_is_fractional() -> None:
    assert band_mask(0.35, 10).tolist() == pytest.approx([1.0, 1.0, 1.0, 0.5] + [0.0] * 6)
    assert band_mask(0.0, 3).tolist() == [0.0, 0.0, 0.0]
    assert band_mask(1.0, 3).tolist() == [1.0, 1.0, 1.0]


def test_the_encoding_keeps_the_raw_input_and_masks_sine_and_cosine_together() -> None:
    x = torch.tensor([[0.25, -0.5, 0.1]])
    mask = torch.tensor([1.0, 0.5, 0.0])
    want = [0.25, -0.5, 0.1]
    for k, weight in enumerate(mask.tolist()):
        angles = [math.pi * 2**k * v for v in (0.25, -0.5, 0.1)]
        want += [weight * math.sin(a) for a in angles] + [weight * math.cos(a) for a in angles]
    got = encode(x, mask)
    assert got.shape[-1] == encoded_width(3, 3) == len(want)
    assert got[0].tolist() == pytest.approx(want, abs=1e-6)


def test_a_share_outside_zero_to_one_is_refused() -> None:
    with pytest.raises(ValueError, match="visible share"):
        band_mask(1.5, 4)
