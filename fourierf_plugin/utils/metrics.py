"""Image-quality metrics (PSNR, SSIM) matching the TensoRF / FourieRF evaluation code, in plain torch.

Images are float tensors ``[H, W, 3]`` in [0, 1]. SSIM follows the mip-NeRF definition that TensoRF (and hence
FourieRF) reports, not skimage's, so the numbers are comparable with the paper's tables (reference spec, section 5).
"""

from __future__ import annotations

import math

import torch
import torch.nn.functional as F

from fourierf_plugin.utils.errors import UserError

MSE_FLOOR = 1e-10  # identical images give 100 dB instead of inf (spec 7.12)

SSIM_WINDOW = 11
SSIM_SIGMA = 1.5
SSIM_K1 = 0.01
SSIM_K2 = 0.03


def _as_bhwc(img: torch.Tensor, name: str) -> torch.Tensor:
    if img.ndim not in (3, 4) or img.shape[-1] != 3:
        raise ValueError(f"{name} must be [H, W, 3] or [B, H, W, 3], got {tuple(img.shape)}")
    return img if img.ndim == 4 else img.unsqueeze(0)


def psnr(pred: torch.Tensor, gt: torch.Tensor) -> float:
    """PSNR in dB of clamped float images; MSE is floored so identical images give 100 dB, never inf.

    Any shape is accepted; the MSE is taken over all elements, so pass one image at a time for per-image PSNR.
    """
    if pred.shape != gt.shape:
        raise ValueError(f"psnr: shapes differ, {tuple(pred.shape)} vs {tuple(gt.shape)}")
    p = pred.detach().to(torch.float64).clamp(0.0, 1.0)
    g = gt.detach().to(torch.float64).clamp(0.0, 1.0)
    mse = max(float(torch.mean((p - g) ** 2)), MSE_FLOOR)
    return -10.0 * math.log10(mse)


def _gaussian_kernel(size: int, sigma: float, dtype: torch.dtype, device: torch.device) -> torch.Tensor:
    # mip-NeRF's taps: t = i - size // 2 + shift, which for odd size is the symmetric (i - (size - 1) / 2).
    t = torch.arange(size, dtype=dtype, device=device) - (size - 1) / 2.0
    k = torch.exp(-0.5 * (t / sigma) ** 2)
    return k / k.sum()


def ssim(pred: torch.Tensor, gt: torch.Tensor) -> float:
    """Mean SSIM (mip-NeRF / TensoRF variant): 11x11 Gaussian (sigma 1.5), separable 'valid' filtering per channel.

    Computed in float64 so float32 and float64 inputs agree; needs at least 11x11 pixels because of 'valid' mode.
    A batch ``[B, H, W, 3]`` gives the mean over its images (all the same size, so the mean of per-image SSIMs).
    """
    if pred.shape != gt.shape:
        raise ValueError(f"ssim: shapes differ, {tuple(pred.shape)} vs {tuple(gt.shape)}")
    p = _as_bhwc(pred, "pred")
    g = _as_bhwc(gt, "gt")
    h, w = int(p.shape[1]), int(p.shape[2])
    if h < SSIM_WINDOW or w < SSIM_WINDOW:
        raise UserError(
            f"SSIM needs at least {SSIM_WINDOW}x{SSIM_WINDOW} pixels, got {h}x{w}",
            "render at a larger size / use a smaller --downscale",
        )
    # [B*3, 1, H, W]: every channel of every image filtered independently.
    x = p.detach().to(torch.float64).permute(0, 3, 1, 2).reshape(-1, 1, h, w)
    y = g.detach().to(torch.float64).permute(0, 3, 1, 2).reshape(-1, 1, h, w)
    k = _gaussian_kernel(SSIM_WINDOW, SSIM_SIGMA, torch.float64, x.device)
    kh = k.view(1, 1, -1, 1)
    kw = k.view(1, 1, 1, -1)

    def filt(z: torch.Tensor) -> torch.Tensor:
        return F.conv2d(F.conv2d(z, kh), kw)

    mu0, mu1 = filt(x), filt(y)
    mu00, mu11, mu01 = mu0 * mu0, mu1 * mu1, mu0 * mu1
    sigma00 = (filt(x * x) - mu00).clamp_min(0.0)
    sigma11 = (filt(y * y) - mu11).clamp_min(0.0)
    sigma01 = filt(x * y) - mu01
    # Cauchy-Schwarz clip: rounding can push |cov| above sqrt(var0 * var1).
    sigma01 = torch.sign(sigma01) * torch.minimum(torch.sqrt(sigma00 * sigma11), sigma01.abs())

    c1 = (SSIM_K1 * 1.0) ** 2
    c2 = (SSIM_K2 * 1.0) ** 2
    numer = (2 * mu01 + c1) * (2 * sigma01 + c2)
    denom = (mu00 + mu11 + c1) * (sigma00 + sigma11 + c2)
    return float((numer / denom).mean())


def mean_and_std(values: list[float]) -> tuple[float, float]:
    """Mean and population standard deviation, as eval reports print them; (nan, nan) for an empty list."""
    if len(values) == 0:
        return float("nan"), float("nan")
    n = len(values)
    mean = sum(values) / n
    var = sum((v - mean) ** 2 for v in values) / n
    return float(mean), float(math.sqrt(var))
