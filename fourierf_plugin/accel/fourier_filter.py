"""The Fourier low-pass of ``field_components.fourier``, faster: a self-adjoint backward and a matrix form.

Both filters are real, even convolutions (the masks are real and symmetric under k -> -k), so each is its own
adjoint: the backward pass applies the same filter to the incoming gradient (``_LowPass``). That gives exactly the
autograd gradient and lets the profiler charge the backward to the filtering.

Planes are filtered by FFTs or, where cheaper (small cutoffs, nearly full bands, sizes with large prime factors such
as fern's NDC grids), by the same operator in matrix form: a real DFT along W over the rfft columns the disc cuts,
a circulant low-pass along H per column, and irfft's synthesis (``_band_operators``). A cost model picks the form.
"""

from __future__ import annotations

import math
from functools import lru_cache

import torch
from torch import Tensor

from fourierf_plugin.field_components import fourier
from fourierf_plugin.field_components.fourier import (
    check_cutoff,
    check_plane_filter,
    device_key,
    disc_radius_sq,
    line_weights,
    plane_is_full,
    plane_mask_cached,
    signed_frequencies,
    unfiltered_planes,
    work_dtype,
)
from fourierf_plugin.utils.phases import phase

_CACHE_SIZE = 256

# The cost model's constants, measured on this project's development machine (2 cores of an x86-64 server CPU,
# torch 2.13 CPU build with 2 threads, pocketfft). Another machine may want others: the choice only moves time
# between two exact forms of the same filter, never the result.
BUTTERFLIES_PER_MULTIPLY_ADD = 3.5
"""How many multiply-adds of a float32 matmul cost as much as one butterfly of an FFT pair."""
FFT_SLOWDOWN: tuple[tuple[int, int], ...] = ((7, 1), (50, 2))
"""(largest prime factor up to, slowdown) of an FFT length against a 7-smooth one: x2 with factors up to 50."""
FFT_SLOWDOWN_OTHERWISE = 4
"""Slowdown of lengths with a larger prime factor (pocketfft falls back to Bluestein's algorithm)."""


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


def filter_lines(lines: Tensor, f: float) -> Tensor:
    """``fourier.filter_lines`` with the self-adjoint backward (the same rfft pair, charged to the filtering)."""
    f = check_cutoff(f)
    if lines.dim() == 0 or line_weights(lines.shape[-1], f)[1]:
        return fourier.filter_lines(lines, f)  # the identity (or the reference's error for a bad shape)
    return _LowPass.apply(lines, lambda x: fourier.apply_line_mask(x, f))  # checked once, here


def _fft_slowdown(n: int) -> int:
    """How much slower than a 7-smooth size an FFT of length ``n`` runs, from its largest prime factor
    (``FFT_SLOWDOWN``; fern's NDC grids have 71, 79 and 47)."""
    largest, m = 1, n
    for p in range(2, math.isqrt(n) + 1):
        while m % p == 0:
            largest, m = p, m // p
    largest = max(largest, m)
    return next((slowdown for bound, slowdown in FFT_SLOWDOWN if largest <= bound), FFT_SLOWDOWN_OTHERWISE)


@lru_cache(maxsize=_CACHE_SIZE)
def _column_reach(height: int, width: int, f: float) -> tuple[int, ...]:
    """Per rfft column ``kw = 0..W//2``: the largest kept ``|kh|`` (``kh^2 <= rho^2 - kw^2``), -1 if none is kept.

    A column with reach ``H//2`` keeps every kh (its low-pass is the identity). Reaches never increase with kw.
    """
    r2 = disc_radius_sq(height, width, f)
    return tuple(
        min(height // 2, math.isqrt(math.floor(r2 - kw * kw))) if kw * kw <= r2 else -1 for kw in range(width // 2 + 1)
    )


def _band_span(height: int, width: int, f: float) -> tuple[int, int, bool]:
    """The rfft columns ``[start, stop)`` the matrix form works on, and whether it filters the complement.

    Direct: the columns that keep anything (a prefix). Complement, ``P - (I - filter) P``: the columns that do not
    keep everything (a suffix), fewer once the disc covers whole columns (wide bands).
    """
    reach = _column_reach(height, width, f)
    kept = sum(r >= 0 for r in reach)
    whole = sum(r == height // 2 for r in reach)
    if len(reach) - whole < kept:
        return whole, len(reach), True
    return 0, kept, False


def _prefer_band(height: int, width: int, f: float) -> bool:
    """Whether the matrix form of the filter (``_band_operators``) is cheaper than an rfft2/irfft2 pair.

    Per plane row the matrices cost ``K (2W + H)`` multiply-pairs for the ``K`` columns they touch, and the FFT pair
    about ``W log2(HW)`` butterflies times the size's slowdown (``BUTTERFLIES_PER_MULTIPLY_ADD``). Small cutoffs and
    awkward sizes go to the matrices, wide bands on smooth sizes to the FFTs.
    """
    slowdown = max(_fft_slowdown(height), _fft_slowdown(width))
    start, stop, _ = _band_span(height, width, f)
    band_cost = (stop - start) * (2 * width + height)
    return band_cost < BUTTERFLIES_PER_MULTIPLY_ADD * width * math.log2(height * width) * slowdown


@lru_cache(maxsize=_CACHE_SIZE)
def _rdft_tables(width: int, device: str, dtype: torch.dtype) -> tuple[Tensor, Tensor]:
    """Real DFT along W for every rfft column: analysis [W, 2, W//2+1] (cos, -sin) and synthesis [2, W//2+1, W] with
    irfft's Hermitian weights (1 for DC and Nyquist, 2 otherwise) and the 1/W."""
    kw = torch.arange(width // 2 + 1, dtype=torch.float64)
    angle = 2 * math.pi * torch.arange(width, dtype=torch.float64)[:, None] * kw[None, :] / width  # [W, K]
    analysis = torch.stack([angle.cos(), -angle.sin()], dim=1)
    weight = torch.full_like(kw, 2.0)
    weight[0] = 1.0
    if width % 2 == 0:
        weight[-1] = 1.0
    synthesis = analysis.permute(1, 2, 0) * weight[:, None] / width
    return analysis.to(device=device, dtype=dtype), synthesis.to(device=device, dtype=dtype).contiguous()


@lru_cache(maxsize=_CACHE_SIZE)
def _lowpass_kernels(height: int, device: str, dtype: torch.dtype) -> tuple[Tensor, Tensor]:
    """Circular low-pass kernels along H: row ``m`` [H//2+1, H] keeps the frequencies ``|kh| <= m`` (impulse
    response over the lag), and the lag index ``(h - g) mod H`` [H, H] that turns a kernel into its circulant."""
    kh = signed_frequencies(height).to(torch.float64)
    lag = torch.arange(height, dtype=torch.float64)
    keeps = kh.abs()[None, :] <= torch.arange(height // 2 + 1, dtype=torch.float64)[:, None]  # [M, H freqs]
    kernels = (keeps.to(torch.float64) @ torch.cos(2 * math.pi * kh[:, None] * lag[None, :] / height)) / height
    lags = (torch.arange(height)[:, None] - torch.arange(height)[None, :]) % height
    return kernels.to(device=device, dtype=dtype), lags.to(device)


@lru_cache(maxsize=4)  # the planes of one iteration (three shapes, one cutoff); the cutoff moves every step
def _band_operators(
    height: int, width: int, f: float, device: str, dtype: torch.dtype
) -> tuple[Tensor, Tensor, Tensor, bool]:
    """The disc low-pass (no leakage) as three real operators on the rfft columns of ``_band_span``.

    ``forward`` [W, 2K] is the real DFT along W (cos | -sin), ``columns`` [K, H, H] holds, for each column ``kw``,
    the low-pass along H that keeps ``kh^2 <= rho^2 - kw^2`` (a real symmetric circulant, since the kept set is
    symmetric in kh; it filters the cos and the sin part alike), or identity minus it for the complement, and
    ``inverse`` [2K, W] is irfft's synthesis. Direct: the filter is their product; complement: P minus it. Either
    way it is exactly ``irfft2(rfft2(P) * disc)``.
    """
    start, stop, complement = _band_span(height, width, f)
    analysis, synthesis = _rdft_tables(width, device, dtype)
    kernels, lags = _lowpass_kernels(height, device, dtype)
    reach = torch.tensor(_column_reach(height, width, f)[start:stop], dtype=torch.long, device=kernels.device)
    chosen = torch.where(reach[:, None] >= 0, kernels[reach.clamp(min=0)], 0.0)  # reach -1: nothing kept
    if complement:
        chosen = -chosen
        chosen[:, 0] += 1.0  # identity minus the low-pass: the impulse at lag 0
    k = stop - start
    forward = analysis[:, :, start:stop].reshape(width, 2 * k)
    return forward, chosen[:, lags], synthesis[:, start:stop].reshape(2 * k, width), complement


def _band_filter(x: Tensor, operators: tuple[Tensor, Tensor, Tensor, bool], leakage: float) -> Tensor:
    forward, columns, inverse, complement = operators
    height, width = x.shape[-2:]
    k = columns.shape[0]
    rows = x.reshape(-1, height, width)
    batch = rows.shape[0]
    # [B, H, 2, K] -> [K, H, 2B]: one matmul per column, applied to its cos and sin parts together.
    spectrum = (rows @ forward).view(batch, height, 2, k).permute(3, 1, 2, 0).reshape(k, height, 2 * batch)
    filtered = torch.bmm(columns, spectrum).view(k, height, 2, batch).permute(3, 1, 2, 0).reshape(batch, height, 2 * k)
    out = (filtered @ inverse).reshape(x.shape)
    if complement:
        out = x - out
    return out + leakage * x if leakage else out


def filter_planes(planes: Tensor, f: float, leakage: float = 0.0, matrix_form: bool = True) -> Tensor:
    """``fourier.filter_planes`` in FFT or matrix form, whichever the cost model says is cheaper (FFT only unless
    ``matrix_form``), with the self-adjoint backward. Exact either way (the tests compare both with the reference to
    1e-11 in float64)."""
    f, leakage, height, width = check_plane_filter(planes, f, leakage)
    if plane_is_full(height, width, f):
        return unfiltered_planes(planes, leakage)
    dtype = work_dtype(planes)
    device = device_key(planes.device)
    if matrix_form and _prefer_band(height, width, f):
        operators = _band_operators(height, width, f, device, dtype)

        def lowpass(x: Tensor) -> Tensor:
            return _band_filter(x, operators, leakage)
    else:
        mask = plane_mask_cached(height, width, f, leakage, device, dtype)

        def lowpass(x: Tensor) -> Tensor:
            return torch.fft.irfft2(torch.fft.rfft2(x, dim=(-2, -1)) * mask, s=(height, width), dim=(-2, -1))

    def apply(x: Tensor) -> Tensor:
        return lowpass(x.to(dtype)).to(x.dtype)

    return _LowPass.apply(planes, apply)
