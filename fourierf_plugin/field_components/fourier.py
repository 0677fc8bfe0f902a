"""Fourier low-pass filters for TensoRF lines and planes (FourieRF, spec 4.2-4.3).

Pure, differentiable functions: the filtered grids are rebuilt from the raw parameters every iteration with autograd
on, so gradients reach the raw tensors only through the kept band. The only state is an LRU cache of masks, which
depend on (shape, cutoff) alone.

Semantics follow the official code, which uses different cutoff conventions for the two kinds of tensor:

* lines: ``c = R*f`` with ``R = L//2 + 1`` rfft bins (``f`` is a fraction of Nyquist). Bins below ``floor(c)`` are
  kept, bin ``floor(c)`` is weighted by the fractional part, so the filter is continuous in ``f``; ``c < 1`` keeps DC.
* planes: a binary disc ``dist <= f*max(H, W)/sqrt(2)`` (``f`` times the half-diagonal) around DC, measured in
  integer frequency units, so non-square planes get an anisotropic band. ``f = 1`` keeps everything. The official
  code adds ``1e-6`` everywhere (``leakage``); the paper zeroes out-of-band coefficients (``leakage = 0``).

Both filters are real, even convolutions (the masks are real and symmetric under k -> -k), so each is its own
adjoint: the backward pass applies the same filter to the incoming gradient (``_LowPass``). That gives exactly the
autograd gradient and lets the profiler charge the backward FFTs to the filtering.

Both filters are circular: energy leaks across opposite faces of the AABB (an impulse on one border shows up on the
other). That is what the method does, so it is kept and documented rather than padded away.
"""

from __future__ import annotations

import math
from functools import lru_cache

import torch
from torch import Tensor

from fourierf_plugin.utils.phases import phase

__all__ = [
    "OFFICIAL_PLANE_LEAKAGE",
    "filter_lines",
    "filter_planes",
    "kept_fraction_lines",
    "kept_fraction_planes",
    "line_mask",
    "plane_mask",
]

OFFICIAL_PLANE_LEAKAGE = 1e-6
"""Out-of-band weight the official code adds to every plane-mask entry (the paper uses 0)."""

_CACHE_SIZE = 256


# ----------------------------------------------------------------------------------------------------------- checks
def _check_cutoff(f: float) -> float:
    try:
        value = float(f)
    except (TypeError, ValueError) as err:
        raise ValueError(f"Fourier cutoff f must be a number in [0, 1], got {f!r}") from err
    if not 0.0 <= value <= 1.0:  # also false for NaN
        raise ValueError(f"Fourier cutoff f must lie in [0, 1] (0 keeps only DC, 1 keeps every frequency), got {f!r}")
    return value


def _check_size(name: str, n: int) -> int:
    if isinstance(n, bool) or not isinstance(n, int) or n < 1:
        raise ValueError(f"{name} must be a positive integer, got {n!r}")
    return n


def _check_leakage(leakage: float) -> float:
    value = float(leakage)
    if not (math.isfinite(value) and value >= 0.0):
        raise ValueError(f"plane-mask leakage must be a finite number >= 0, got {leakage!r}")
    return value


def _device_key(device: torch.device | str | None) -> str:
    return str(torch.device("cpu") if device is None else torch.device(device))


def _fft_dtype(x: Tensor) -> torch.dtype:
    """FFTs need float32/float64; half-precision inputs are filtered in float32 and cast back."""
    return x.dtype if x.dtype in (torch.float32, torch.float64) else torch.float32


class _LowPass(torch.autograd.Function):
    """A self-adjoint linear filter: the gradient of ``apply(x)`` is ``apply(grad)``."""

    @staticmethod
    def forward(ctx, x: Tensor, apply) -> Tensor:  # type: ignore[override]
        ctx.filter_fn = apply
        return apply(x)

    @staticmethod
    def backward(ctx, grad: Tensor) -> tuple[Tensor, None]:  # type: ignore[override]
        with phase("fourier_filter_backward"):
            return ctx.filter_fn(grad), None


# ------------------------------------------------------------------------------------------------------------ lines
@lru_cache(maxsize=_CACHE_SIZE)
def _line_weights(length: int, f: float) -> tuple[tuple[float, ...], bool]:
    """Per-bin weights of the line mask and whether they are all 1 (the filter is then the identity)."""
    bins = length // 2 + 1
    c = bins * f
    if c < 1.0:
        weights = [1.0] + [0.0] * (bins - 1)
    elif c >= bins:
        weights = [1.0] * bins
    else:
        k = math.floor(c)
        weights = [1.0] * k + [c - k] + [0.0] * (bins - k - 1)
    return tuple(weights), all(w == 1.0 for w in weights)


@lru_cache(maxsize=_CACHE_SIZE)
def _line_mask_cached(length: int, f: float, device: str, dtype: torch.dtype) -> Tensor:
    weights, _ = _line_weights(length, f)
    return torch.tensor(weights, dtype=torch.float64).to(device=device, dtype=dtype)


def line_mask(
    length: int, f: float, *, device: torch.device | str | None = None, dtype: torch.dtype = torch.float32
) -> Tensor:
    """rfft-layout mask ``[length//2 + 1]`` of the line low-pass at cutoff ``f`` (spec 4.2).

    The tensor is cached and shared: callers must not modify it in place.
    """
    length = _check_size("line length", length)
    return _line_mask_cached(length, _check_cutoff(f), _device_key(device), dtype)


def filter_lines(lines: Tensor, f: float) -> Tensor:
    """Low-pass ``lines`` along the last dim: ``irfft(rfft(x) * mask, n=L)``.

    Leading dims are batch dims (``[C, L]``, ``[1, C, L]``); TensoRF's ``[1, C, L, 1]`` lines are passed with L
    last (``x.squeeze(-1)``). A mask of all ones returns ``lines`` itself, so ``f = 1`` is exactly unfiltered TensoRF.
    """
    f = _check_cutoff(f)
    length = _check_size("line length (last dim)", lines.shape[-1] if lines.dim() > 0 else 0)
    _, full = _line_weights(length, f)
    if full:
        return lines
    work_dtype = _fft_dtype(lines)
    mask = _line_mask_cached(length, f, _device_key(lines.device), work_dtype)

    def apply(x: Tensor) -> Tensor:
        spectrum = torch.fft.rfft(x.to(work_dtype), dim=-1)
        return torch.fft.irfft(spectrum * mask, n=length, dim=-1).to(x.dtype)

    return _LowPass.apply(lines, apply)


def kept_fraction_lines(length: int, f: float) -> float:
    """Share of the full (two-sided) spectrum a line keeps, for logging; about ``f``."""
    length = _check_size("line length", length)
    weights, _ = _line_weights(length, _check_cutoff(f))
    # Every rfft bin except DC (and Nyquist for even L) stands for a +k/-k pair in the full spectrum.
    total = 0.0
    for k, w in enumerate(weights):
        paired = k != 0 and not (length % 2 == 0 and k == length // 2)
        total += w * (2.0 if paired else 1.0)
    return total / length


# ----------------------------------------------------------------------------------------------------------- planes
def _signed_freqs(n: int) -> Tensor:
    """Integer frequencies in ``fft`` order, i.e. ``fftfreq(n) * n`` without the float round trip."""
    idx = torch.arange(n, dtype=torch.int64)
    return (idx + n // 2) % n - n // 2


def _radius_sq(height: int, width: int, f: float) -> float:
    """``rho^2`` with ``rho = f * max(H, W) / sqrt(2)``; squared so that f = 1 compares exactly."""
    return f * f * max(height, width) ** 2 / 2.0


def _plane_full(height: int, width: int, f: float) -> bool:
    """Whether the disc covers every frequency (the farthest one sits at ``(H//2, W//2)``)."""
    return (height // 2) ** 2 + (width // 2) ** 2 <= _radius_sq(height, width, f)


@lru_cache(maxsize=_CACHE_SIZE)
def _plane_mask_cached(height: int, width: int, f: float, leakage: float, device: str, dtype: torch.dtype) -> Tensor:
    kh = _signed_freqs(height).to(torch.float64)[:, None]
    kw = torch.arange(width // 2 + 1, dtype=torch.float64)[None, :]
    inside = (kh * kh + kw * kw) <= _radius_sq(height, width, f)
    mask = inside.to(torch.float64) + leakage
    return mask.to(device=device, dtype=dtype)


def plane_mask(
    height: int,
    width: int,
    f: float,
    leakage: float = 0.0,
    *,
    device: torch.device | str | None = None,
    dtype: torch.dtype = torch.float32,
) -> Tensor:
    """rfft2-layout (unshifted) mask ``[H, W//2 + 1]``: ``1[dist <= rho] + leakage`` (spec 4.3).

    ``dist`` is the length of the signed integer frequency ``(kh, kw)``; this equals the reference disc centred at
    ``(H//2, W//2)`` of the fftshift-ed spectrum, for odd and even and non-square sizes. Cached and shared: callers
    must not modify it in place.
    """
    height = _check_size("plane height", height)
    width = _check_size("plane width", width)
    return _plane_mask_cached(height, width, _check_cutoff(f), _check_leakage(leakage), _device_key(device), dtype)


def filter_planes(planes: Tensor, f: float, leakage: float = 0.0) -> Tensor:
    """Low-pass ``planes`` over the last two dims: ``irfft2(rfft2(P) * mask, s=(H, W))``.

    When the disc covers every frequency the FFT is skipped: ``planes`` itself is returned without leakage, and
    ``planes * (1 + leakage)`` with it (what the official mask ``1 + 1e-6`` does).
    """
    f = _check_cutoff(f)
    leakage = _check_leakage(leakage)
    if planes.dim() < 2:
        raise ValueError(
            f"filter_planes needs a tensor with at least 2 dims [..., H, W], got shape {tuple(planes.shape)}"
        )
    height = _check_size("plane height (dim -2)", planes.shape[-2])
    width = _check_size("plane width (dim -1)", planes.shape[-1])
    if _plane_full(height, width, f):
        return planes if leakage == 0.0 else planes * (1.0 + leakage)
    work_dtype = _fft_dtype(planes)
    mask = _plane_mask_cached(height, width, f, leakage, _device_key(planes.device), work_dtype)

    def apply(x: Tensor) -> Tensor:
        spectrum = torch.fft.rfft2(x.to(work_dtype), dim=(-2, -1))
        return torch.fft.irfft2(spectrum * mask, s=(height, width), dim=(-2, -1)).to(x.dtype)

    return _LowPass.apply(planes, apply)


def kept_fraction_planes(height: int, width: int, f: float) -> float:
    """Share of the full spectrum inside the disc (leakage ignored), for logging; about ``pi f^2 / 2`` if square."""
    height = _check_size("plane height", height)
    width = _check_size("plane width", width)
    f = _check_cutoff(f)
    kh = _signed_freqs(height).to(torch.float64)[:, None]
    kw = _signed_freqs(width).to(torch.float64)[None, :]
    inside = (kh * kh + kw * kw) <= _radius_sq(height, width, f)
    return float(inside.sum().item()) / (height * width)
