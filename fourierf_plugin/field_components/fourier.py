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

Planes are filtered by FFTs or, where cheaper (small cutoffs, nearly full bands, sizes with large prime factors such
as fern's NDC grids), by the same operator in matrix form: a real DFT along W over the rfft columns the disc cuts,
a circulant low-pass along H per column, and irfft's synthesis (``_band_operators``).

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


def _fft_slowdown(n: int) -> int:
    """How much slower than a 7-smooth size an FFT of length ``n`` runs (pocketfft, timed on this CPU): ~2x with a
    prime factor up to 50, ~4x above (Bluestein; fern's NDC grids have 71, 79 and 47)."""
    largest, m = 1, n
    for p in range(2, math.isqrt(n) + 1):
        while m % p == 0:
            largest, m = p, m // p
    largest = max(largest, m)
    return 1 if largest <= 7 else 2 if largest <= 50 else 4


@lru_cache(maxsize=_CACHE_SIZE)
def _column_reach(height: int, width: int, f: float) -> tuple[int, ...]:
    """Per rfft column ``kw = 0..W//2``: the largest kept ``|kh|`` (``kh^2 <= rho^2 - kw^2``), -1 if none is kept.

    A column with reach ``H//2`` keeps every kh (its low-pass is the identity). Reaches never increase with kw.
    """
    r2 = _radius_sq(height, width, f)
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
    about ``W log2(HW)`` butterflies times the size's slowdown; a multiply-add in a matmul ran ~3.5x cheaper than a
    butterfly on this CPU (2 threads). Small cutoffs and awkward sizes go to the matrices, wide bands on smooth
    sizes to the FFTs.
    """
    slowdown = max(_fft_slowdown(height), _fft_slowdown(width))
    start, stop, _ = _band_span(height, width, f)
    band_cost = (stop - start) * (2 * width + height)
    return band_cost < 3.5 * width * math.log2(height * width) * slowdown


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
    kh = _signed_freqs(height).to(torch.float64)
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
    device = _device_key(planes.device)
    if _prefer_band(height, width, f):
        operators = _band_operators(height, width, f, device, work_dtype)

        def lowpass(x: Tensor) -> Tensor:
            return _band_filter(x, operators, leakage)
    else:
        mask = _plane_mask_cached(height, width, f, leakage, device, work_dtype)

        def lowpass(x: Tensor) -> Tensor:
            return torch.fft.irfft2(torch.fft.rfft2(x, dim=(-2, -1)) * mask, s=(height, width), dim=(-2, -1))

    def apply(x: Tensor) -> Tensor:
        return lowpass(x.to(work_dtype)).to(x.dtype)

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
