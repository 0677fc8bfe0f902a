"""PSNR / SSIM / mean_and_std: known values, agreement with skimage, symmetry, dtype independence, tiny images."""

from __future__ import annotations

import math

import numpy as np
import pytest
import torch
from scipy.ndimage import gaussian_filter
from skimage.metrics import structural_similarity

from fourierf_plugin.utils.errors import UserError
from fourierf_plugin.utils.metrics import mean_and_std, psnr, ssim


def _smooth_image(seed: int, h: int = 48, w: int = 40, sigma: float = 3.0) -> np.ndarray:
    """Random, spatially smooth image in [0, 1] (smoothing keeps local statistics well-conditioned)."""
    rng = np.random.default_rng(seed)
    img = gaussian_filter(rng.random((h, w, 3)), sigma=(sigma, sigma, 0))
    img = (img - img.min()) / (img.max() - img.min())
    return img


def _noisy(img: np.ndarray, seed: int, amount: float = 0.1) -> np.ndarray:
    rng = np.random.default_rng(seed)
    noise = gaussian_filter(rng.standard_normal(img.shape), sigma=(1.0, 1.0, 0))
    return np.clip(img + amount * noise, 0.0, 1.0)


def test_psnr_constant_offset_is_20db() -> None:
    gt = torch.full((8, 8, 3), 0.5)
    assert psnr(gt + 0.1, gt) == pytest.approx(20.0, abs=1e-5)
    assert psnr(gt - 0.1, gt) == pytest.approx(20.0, abs=1e-5)


def test_psnr_identical_is_100db_not_inf() -> None:
    img = torch.rand(16, 16, 3)
    value = psnr(img, img.clone())
    assert math.isfinite(value)
    assert value == pytest.approx(100.0)


def test_psnr_clamps_inputs() -> None:
    gt = torch.ones(4, 4, 3)
    # pred above 1 clamps to gt exactly: identical after clamping.
    assert psnr(gt + 5.0, gt) == pytest.approx(100.0)
    assert psnr(torch.full((4, 4, 3), -1.0), torch.full((4, 4, 3), 0.1)) == pytest.approx(20.0, abs=1e-5)


def test_ssim_identical_is_one() -> None:
    img = torch.from_numpy(_smooth_image(0))
    assert ssim(img, img.clone()) == pytest.approx(1.0, abs=1e-6)
    flat = torch.full((16, 16, 3), 0.3)
    assert ssim(flat, flat.clone()) == pytest.approx(1.0, abs=1e-6)


@pytest.mark.parametrize("seed", [1, 2, 3])
def test_ssim_matches_skimage_gaussian(seed: int) -> None:
    gt = _smooth_image(seed)
    pred = _noisy(gt, seed + 100)
    ours = ssim(torch.from_numpy(pred), torch.from_numpy(gt))
    ref = structural_similarity(
        pred,
        gt,
        gaussian_weights=True,
        sigma=1.5,
        use_sample_covariance=False,
        data_range=1.0,
        channel_axis=-1,
    )
    # skimage crops the same 5-pixel border ('valid' region) before averaging, and does not clip the covariance;
    # on smooth images that clip is inactive, so the two agree to rounding (observed ~1e-15).
    assert 0.3 < ours < 0.999
    assert abs(ours - ref) < 1e-6


def test_ssim_drops_with_more_noise() -> None:
    gt = _smooth_image(4)
    values = [ssim(torch.from_numpy(_noisy(gt, 5, a)), torch.from_numpy(gt)) for a in (0.02, 0.1, 0.3)]
    assert values[0] > values[1] > values[2]


def test_ssim_symmetric() -> None:
    a = torch.from_numpy(_smooth_image(6))
    b = torch.from_numpy(_noisy(_smooth_image(6), 7, 0.2))
    assert ssim(a, b) == pytest.approx(ssim(b, a), abs=1e-12)


@pytest.mark.parametrize("shape", [(10, 32, 3), (32, 10, 3), (5, 5, 3)])
def test_ssim_tiny_image_is_user_error(shape: tuple[int, int, int]) -> None:
    img = torch.rand(shape)
    with pytest.raises(UserError, match=r"SSIM needs at least 11x11 pixels") as info:
        ssim(img, img)
    assert f"{shape[0]}x{shape[1]}" in info.value.problem
    assert info.value.fix


def test_ssim_exactly_11x11_works() -> None:
    img = torch.rand(11, 11, 3)
    assert ssim(img, img) == pytest.approx(1.0, abs=1e-6)


def test_ssim_float32_and_float64_agree() -> None:
    gt = _smooth_image(8)
    pred = _noisy(gt, 9)
    v64 = ssim(torch.from_numpy(pred), torch.from_numpy(gt))
    v32 = ssim(torch.from_numpy(pred).float(), torch.from_numpy(gt).float())
    assert v32 == pytest.approx(v64, abs=1e-6)
    p64 = psnr(torch.from_numpy(pred), torch.from_numpy(gt))
    p32 = psnr(torch.from_numpy(pred).float(), torch.from_numpy(gt).float())
    assert p32 == pytest.approx(p64, abs=1e-4)


def test_ssim_batch_is_mean_of_images() -> None:
    gts = [_smooth_image(s) for s in (10, 11)]
    preds = [_noisy(g, s + 50) for s, g in zip((10, 11), gts, strict=True)]
    singles = [ssim(torch.from_numpy(p), torch.from_numpy(g)) for p, g in zip(preds, gts, strict=True)]
    batch = ssim(torch.from_numpy(np.stack(preds)), torch.from_numpy(np.stack(gts)))
    assert batch == pytest.approx(sum(singles) / 2, abs=1e-12)


def test_ssim_covariance_clip_keeps_value_bounded() -> None:
    # Anti-correlated images: SSIM must stay within [-1, 1].
    img = torch.from_numpy(_smooth_image(12))
    value = ssim(img, 1.0 - img)
    assert -1.0 <= value < 0.0


def test_mean_and_std_population() -> None:
    mean, std = mean_and_std([1.0, 2.0, 3.0, 4.0])
    assert mean == pytest.approx(2.5)
    assert std == pytest.approx(float(np.std([1.0, 2.0, 3.0, 4.0])))
    assert mean_and_std([7.0]) == (7.0, 0.0)
    m, s = mean_and_std([])
    assert math.isnan(m) and math.isnan(s)
