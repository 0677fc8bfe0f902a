"""FreeNeRF's frequency regularisation: a positional encoding whose visible bands open linearly over training.

The encoding of ``x`` is ``[x, sin(2^0 π x), cos(2^0 π x), ..., sin(2^(L-1) π x), cos(2^(L-1) π x)]``. While ``v``
bands are visible (``v`` grows linearly from 0 to L over the ramp), band ``k`` is scaled by ``clip(v - k, 0, 1)``:
bands below ``floor(v)`` are whole, the edge band is the fraction ``v - floor(v)``, the rest are zero; a band's sine
and cosine share their weight, and the raw input ``x`` is always visible.
"""

from __future__ import annotations

import math

import torch
from torch import Tensor


def visible_share(step: int, ramp_steps: int) -> float:
    """The share of the bands visible at ``step`` of a ramp of ``ramp_steps`` (FreeNeRF: t / T, 1 from T on)."""
    if ramp_steps <= 0:
        return 1.0
    return min(1.0, max(0.0, step / ramp_steps))


def band_mask(share: float, bands: int, device: torch.device | str = "cpu") -> Tensor:
    """Weights [bands] of the bands when ``share`` of them are visible: ``clip(share · bands - k, 0, 1)``."""
    if not (math.isfinite(share) and 0.0 <= share <= 1.0):
        raise ValueError(f"the visible share of the bands must be in [0, 1], got {share!r}")
    visible = share * bands
    k = torch.arange(bands, dtype=torch.float32, device=device)
    return (visible - k).clamp(0.0, 1.0)


def encoded_width(dims: int, bands: int) -> int:
    """Width of the encoding of ``dims`` coordinates with ``bands`` bands (the raw input, then sin and cos)."""
    return dims * (1 + 2 * bands)


def encode(x: Tensor, mask: Tensor) -> Tensor:
    """[N, D] -> [N, D (1 + 2L)]: the raw input, then each band's sine and cosine times its weight in ``mask`` [L]."""
    bands = mask.shape[0]
    if bands == 0:
        return x
    scales = math.pi * 2.0 ** torch.arange(bands, dtype=x.dtype, device=x.device)
    angles = x.unsqueeze(-2) * scales.unsqueeze(-1)  # [N, L, D]
    weight = mask.to(x.dtype).unsqueeze(-1)  # [L, 1]
    pairs = torch.cat([torch.sin(angles) * weight, torch.cos(angles) * weight], dim=-1)  # [N, L, 2D]
    return torch.cat([x, pairs.flatten(-2)], dim=-1)
