"""Images for people: float renders to uint8, and depth maps through a perceptual colormap (no matplotlib).

The colormaps are published polynomial fits (turbo: Google AI's 5th-order approximation; viridis: a 6th-order
least-squares fit), close enough to the originals that depth pictures look like nerfstudio's, without the
dependency.
"""

from __future__ import annotations

import sys
from typing import TYPE_CHECKING, Literal, TypeGuard

import numpy as np

if TYPE_CHECKING:
    import torch

Colormap = Literal["turbo", "viridis"]
Background = Literal["white", "black"]

# turbo(x) = sum_k c_k x^k, k = 0..5, one row per channel (Mikhailov 2019, "Turbo, an improved rainbow colormap").
_TURBO = np.array(
    [
        [0.13572138, 4.61539260, -42.66032258, 132.13108234, -152.94239396, 59.28637943],
        [0.09140261, 2.19418839, 4.84296658, -14.18503333, 4.27729857, 2.82956604],
        [0.10667330, 12.64194608, -60.58204836, 110.36276771, -89.90310912, 27.34824973],
    ]
)
# viridis(x) = sum_k c_k x^k, k = 0..6 (perceptually uniform and monotone in lightness).
_VIRIDIS = np.array(
    [
        [0.2777273272234177, 0.1050930431085774, -0.3308618287255563, -4.634230498983486, 6.228269936347081,
         4.776384997670288, -5.435455855934631],
        [0.005407344544966578, 1.404613529898575, 0.214847559468213, -5.799100973351585, 14.17993336680509,
         -13.74514537774601, 4.645852612178535],
        [0.3340998053353061, 1.384590162594685, 0.09509516302823659, -19.33244095627987, 56.69055260068105,
         -65.35303263337234, 26.3124352495832],
    ]
)  # fmt: skip
_COEFFS = {"turbo": _TURBO, "viridis": _VIRIDIS}


def _is_tensor(array: object) -> TypeGuard[torch.Tensor]:
    """Without importing torch (the scene generator uses these helpers and never needs it): a tensor exists only
    once torch is loaded."""
    torch_module = sys.modules.get("torch")
    return torch_module is not None and isinstance(array, torch_module.Tensor)


def _numpy(array: np.ndarray | torch.Tensor) -> np.ndarray:
    if _is_tensor(array):
        return array.detach().float().cpu().numpy()
    return np.asarray(array, dtype=np.float32)


def to_uint8(image: np.ndarray | torch.Tensor) -> np.ndarray:
    """[0, 1] floats (any shape, any channel count) to uint8: clipped to [0, 1], then ``x * 255 + 0.5`` truncated
    (halves round up); NaN becomes 0. A float64 array is rounded in float64, anything else in float32."""
    floats = image if isinstance(image, np.ndarray) and image.dtype == np.float64 else _numpy(image)
    values = np.nan_to_num(floats, nan=0.0, posinf=1.0, neginf=0.0)
    return (np.clip(values, 0.0, 1.0) * 255.0 + 0.5).astype(np.uint8)


def apply_colormap(values: np.ndarray | torch.Tensor, cmap: Colormap = "turbo") -> np.ndarray:
    """Colours [..., 3] float in [0, 1] for ``values`` in [0, 1] (clipped; NaN maps to 0)."""
    if cmap not in _COEFFS:
        raise ValueError(f"unknown colormap {cmap!r}; choose one of {sorted(_COEFFS)}")
    x = np.clip(np.nan_to_num(_numpy(values).astype(np.float64), nan=0.0), 0.0, 1.0)
    coeffs = _COEFFS[cmap]
    powers = x[..., None] ** np.arange(coeffs.shape[1])  # [..., K]
    return np.clip(powers @ coeffs.T, 0.0, 1.0).astype(np.float32)


def depth_range(
    depth: np.ndarray | torch.Tensor,
    accumulation: np.ndarray | torch.Tensor | None = None,
    percentiles: tuple[float, float] = (1.0, 99.0),
) -> tuple[float, float]:
    """Robust (low, high) of the depth of the pixels that hit something (accumulation >= 0.5).

    Percentiles rather than min/max: a few floaters or a background ray at ``far`` would otherwise squeeze the
    object into one colour. Falls back to every finite pixel when nothing is opaque, and to (0, 1) when none is.
    """
    d = _numpy(depth)
    valid = np.isfinite(d)
    if accumulation is not None:
        opaque = valid & (_numpy(accumulation) >= 0.5)
        if opaque.any():
            valid = opaque
    if not valid.any():
        return 0.0, 1.0
    low, high = np.percentile(d[valid], percentiles)
    return float(low), float(high)


def colorize_depth(
    depth: np.ndarray | torch.Tensor,
    accumulation: np.ndarray | torch.Tensor | None = None,
    near: float | None = None,
    far: float | None = None,
    cmap: Colormap = "turbo",
    background: Background = "white",
) -> np.ndarray:
    """uint8 [H, W, 3] picture of ``depth`` [H, W]: near at the low end of ``cmap``, far at the high end.

    The range is ``near``/``far`` when given (fix it across an animation so colours do not flicker), else the 1-99
    percentiles of the opaque pixels. Pixels with accumulation < 0.5 (empty space) are painted ``background``.
    A constant depth maps to the low end instead of dividing by zero.
    """
    d = _numpy(depth)
    if d.ndim != 2:
        raise ValueError(f"depth must be [H, W], got shape {d.shape}")
    low, high = depth_range(d, accumulation)
    low = low if near is None else float(near)
    high = high if far is None else float(far)
    span = high - low
    x = (d - low) / span if span > 1e-12 else np.zeros_like(d)
    colors = apply_colormap(x, cmap)
    if accumulation is not None:
        empty = _numpy(accumulation) < 0.5
        colors[empty] = 1.0 if background == "white" else 0.0
    return to_uint8(colors)


def colorize_accumulation(accumulation: np.ndarray | torch.Tensor) -> np.ndarray:
    """uint8 [H, W, 3] greyscale opacity: white where the ray hit something, black in empty space."""
    grey = to_uint8(_numpy(accumulation))
    return np.repeat(grey[..., None], 3, axis=-1)
