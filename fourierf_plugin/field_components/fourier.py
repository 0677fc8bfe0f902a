"""Fourier low-pass filters for TensoRF lines and planes (FourieRF, spec 4.2-4.3): the reference implementation.

Pure, differentiable functions: the filtered grids are rebuilt from the raw parameters every iteration with autograd
on, so gradients reach the raw tensors only through the kept band. The only state is an LRU cache of masks, which
depend on (shape, cutoff) alone. ``fourierf_plugin.accel.fourier_filter`` computes the same filters faster (a
self-adjoint backward, a matrix form for narrow bands); its tests compare it with these.

Semantics follow the official code, which uses different cutoff conventions for the two kinds of tensor:

* lines: ``c = R*f`` with ``R = L//2 + 1`` rfft bins (``f`` is a fraction of Nyquist). Bins below ``floor(c)`` are
  kept, bin ``floor(c)`` is weighted by the fractional part, so the filter is continuous in ``f``; ``c < 1`` keeps DC.
* planes: a binary disc ``dist <= f*max(H, W)/sqrt(2)`` (``f`` times the half-diagonal) around DC, measured in
  integer frequency units, so non-square planes get an anisotropic band. ``f = 1`` keeps everything. The official
  code adds ``1e-6`` everywhere (``leakage``); the paper zeroes out-of-band coefficients (``leakage = 0``).

Both filters are circular: energy leaks across opposite faces of the AABB (an impulse on one border shows up on the
other). That is what the method does, so it is the default. ``mirrored`` runs either filter on the factor's mirror
image appended to it (a DCT-style low-pass at the same cutoff in cycles per box), so nothing wraps: in NDC the far
wall at z = 1 no longer shows up at the near plane z = -1 while the band is narrow.
"""

from __future__ import annotations

import math
from functools import lru_cache

import torch
from torch import Tensor

__all__ = [
    "OFFICIAL_PLANE_LEAKAGE",
    "apply_line_mask",
    "check_cutoff",
    "check_leakage",
    "check_plane_filter",
    "disc_radius_sq",
    "filter_lines",
    "filter_planes",
    "kept_fraction_lines",
    "kept_fraction_planes",
    "line_mask",
    "line_weights",
    "mirrored",
    "plane_is_full",
    "plane_mask",
    "signed_frequencies",
    "unfiltered_planes",
    "work_dtype",
]

OFFICIAL_PLANE_LEAKAGE = 1e-6
"""Out-of-band weight the official code adds to every plane-mask entry (the paper uses 0)."""

_CACHE_SIZE = 256
_MASK_CACHE_SIZE = 32  # device tensors: the masks of a few cutoffs (renders reuse one; training moves every step)


# ----------------------------------------------------------------------------------------------------------- checks
def check_cutoff(f: float) -> float:
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


def check_leakage(leakage: float) -> float:
    value = float(leakage)
    if not (math.isfinite(value) and value >= 0.0):
        raise ValueError(f"plane-mask leakage must be a finite number >= 0, got {leakage!r}")
    return value


def check_plane_filter(planes: Tensor, f: float, leakage: float) -> tuple[float, float, int, int]:
    """The checked arguments of a plane filter: (f, leakage, H, W) of a [..., H, W] tensor of planes."""
    if planes.dim() < 2:
        raise ValueError(
            f"filter_planes needs a tensor with at least 2 dims [..., H, W], got shape {tuple(planes.shape)}"
        )
    height = _check_size("plane height (dim -2)", planes.shape[-2])
    return check_cutoff(f), check_leakage(leakage), height, _check_size("plane width (dim -1)", planes.shape[-1])


def unfiltered_planes(planes: Tensor, leakage: float) -> Tensor:
    """What a disc covering every frequency leaves: ``planes`` itself, or ``planes * (1 + leakage)`` with leakage
    (what the official mask ``1 + 1e-6`` does)."""
    return planes if leakage == 0.0 else planes * (1.0 + leakage)


def device_key(device: torch.device | str | None) -> str:
    return str(torch.device("cpu") if device is None else torch.device(device))


def work_dtype(x: Tensor) -> torch.dtype:
    """FFTs need float32/float64; half-precision inputs are filtered in float32 and cast back."""
    return x.dtype if x.dtype in (torch.float32, torch.float64) else torch.float32


# ------------------------------------------------------------------------------------------------------------ lines
@lru_cache(maxsize=_CACHE_SIZE)
def line_weights(length: int, f: float) -> tuple[tuple[float, ...], bool]:
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


@lru_cache(maxsize=_MASK_CACHE_SIZE)
def _line_mask_cached(length: int, f: float, device: str, dtype: torch.dtype) -> Tensor:
    """``line_weights`` made on ``device`` (no host copy): bin k keeps clamp(c - k, 0, 1) with c = bins f, DC always."""
    bins = length // 2 + 1
    edge = bins * f
    k = torch.arange(bins, dtype=torch.float64, device=device)
    weights = (edge - k).clamp(0.0, 1.0)
    weights[0] = 1.0
    return weights.to(dtype)


def line_mask(
    length: int, f: float, *, device: torch.device | str | None = None, dtype: torch.dtype = torch.float32
) -> Tensor:
    """rfft-layout mask ``[length//2 + 1]`` of the line low-pass at cutoff ``f`` (spec 4.2).

    The tensor is cached and shared: callers must not modify it in place.
    """
    length = _check_size("line length", length)
    return _line_mask_cached(length, check_cutoff(f), device_key(device), dtype)


def filter_lines(lines: Tensor, f: float) -> Tensor:
    """Low-pass ``lines`` along the last dim: ``irfft(rfft(x) * mask, n=L)``.

    Leading dims are batch dims (``[C, L]``, ``[1, C, L]``); TensoRF's ``[1, C, L, 1]`` lines are passed with L
    last (``x.squeeze(-1)``). A mask of all ones returns ``lines`` itself, so ``f = 1`` is exactly unfiltered TensoRF.
    """
    f = check_cutoff(f)
    length = _check_size("line length (last dim)", lines.shape[-1] if lines.dim() > 0 else 0)
    if line_weights(length, f)[1]:
        return lines
    return apply_line_mask(lines, f)


def apply_line_mask(lines: Tensor, f: float) -> Tensor:
    """The line low-pass itself, ``irfft(rfft(x) * mask)``, for a cutoff and length the caller has checked."""
    length = lines.shape[-1]
    dtype = work_dtype(lines)
    mask = _line_mask_cached(length, f, device_key(lines.device), dtype)
    return torch.fft.irfft(torch.fft.rfft(lines.to(dtype), dim=-1) * mask, n=length, dim=-1).to(lines.dtype)


def kept_fraction_lines(length: int, f: float) -> float:
    """Share of the full (two-sided) spectrum a line keeps, for logging; about ``f``."""
    length = _check_size("line length", length)
    weights, _ = line_weights(length, check_cutoff(f))
    # Every rfft bin except DC (and Nyquist for even L) stands for a +k/-k pair in the full spectrum.
    total = 0.0
    for k, w in enumerate(weights):
        paired = k != 0 and not (length % 2 == 0 and k == length // 2)
        total += w * (2.0 if paired else 1.0)
    return total / length


# ------------------------------------------------------------------------------------------------ mirror boundary
def mirrored(low_pass, x: Tensor, f: float, ndims: int, *args) -> Tensor:
    """``low_pass(x, f, *args)`` with mirror boundaries over the last ``ndims`` dims instead of periodic ones.

    Each of those dims is extended by its reversed copy (``x0 .. x_{L-1}, x_{L-1} .. x0``), the extension is filtered
    at the same ``f`` (the masks scale with length, so the cutoff in cycles per box is unchanged) and cropped back.
    The extension is even and periodic, so it has no jump at the faces and nothing leaks across the box. The filter
    stays linear and self-adjoint (the mask is symmetric), and ``f = 1`` is still the identity.
    """
    if check_cutoff(f) >= 1.0:
        return low_pass(x, f, *args)
    sizes = x.shape[x.dim() - ndims :]
    for dim in range(-ndims, 0):
        x = torch.cat([x, x.flip(dim)], dim=dim)
    out = low_pass(x, f, *args)
    for dim, size in zip(range(-ndims, 0), sizes, strict=True):
        out = out.narrow(dim, 0, size)
    return out


# ----------------------------------------------------------------------------------------------------------- planes
def signed_frequencies(n: int, device: torch.device | str | None = None) -> Tensor:
    """Integer frequencies in ``fft`` order, i.e. ``fftfreq(n) * n`` without the float round trip."""
    idx = torch.arange(n, dtype=torch.int64, device=device)
    return (idx + n // 2) % n - n // 2


def disc_radius_sq(height: int, width: int, f: float) -> float:
    """``rho^2`` with ``rho = f * max(H, W) / sqrt(2)``; squared so that f = 1 compares exactly."""
    return f * f * max(height, width) ** 2 / 2.0


def plane_is_full(height: int, width: int, f: float) -> bool:
    """Whether the disc covers every frequency (the farthest one sits at ``(H//2, W//2)``)."""
    return (height // 2) ** 2 + (width // 2) ** 2 <= disc_radius_sq(height, width, f)


@lru_cache(maxsize=_MASK_CACHE_SIZE)
def plane_mask_cached(height: int, width: int, f: float, leakage: float, device: str, dtype: torch.dtype) -> Tensor:
    """``plane_mask`` made on ``device`` from the cutoff (no host copy while the cutoff moves every step)."""
    kh = signed_frequencies(height, device).to(torch.float64)[:, None]
    kw = torch.arange(width // 2 + 1, dtype=torch.float64, device=device)[None, :]
    inside = (kh * kh + kw * kw) <= disc_radius_sq(height, width, f)
    return (inside.to(torch.float64) + leakage).to(dtype)


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
    return plane_mask_cached(height, width, check_cutoff(f), check_leakage(leakage), device_key(device), dtype)


def filter_planes(planes: Tensor, f: float, leakage: float = 0.0) -> Tensor:
    """Low-pass ``planes`` over the last two dims: ``irfft2(rfft2(P) * mask, s=(H, W))``.

    When the disc covers every frequency the FFT is skipped (``unfiltered_planes``).
    """
    f, leakage, height, width = check_plane_filter(planes, f, leakage)
    if plane_is_full(height, width, f):
        return unfiltered_planes(planes, leakage)
    dtype = work_dtype(planes)
    mask = plane_mask_cached(height, width, f, leakage, device_key(planes.device), dtype)
    spectrum = torch.fft.rfft2(planes.to(dtype), dim=(-2, -1))
    return torch.fft.irfft2(spectrum * mask, s=(height, width), dim=(-2, -1)).to(planes.dtype)


def kept_fraction_planes(height: int, width: int, f: float) -> float:
    """Share of the full spectrum inside the disc (leakage ignored), for logging; about ``pi f^2 / 2`` if square."""
    height = _check_size("plane height", height)
    width = _check_size("plane width", width)
    f = check_cutoff(f)
    kh = signed_frequencies(height).to(torch.float64)[:, None]
    kw = signed_frequencies(width).to(torch.float64)[None, :]
    inside = (kh * kh + kw * kw) <= disc_radius_sq(height, width, f)
    return float(inside.sum().item()) / (height * width)
