"""The reference FourieRF line and plane low-pass filters and their masks (spec 4.2, 4.3, 7.6, 7.7).

What the method computes, checked against the spec written out verbatim (a centred disc on the fftshift-ed full
spectrum) and against its defining properties: f = 1 is the identity, f = 0 keeps the mean, energy never decreases
with f, binary masks are projections, the filter is circular, gradients stay in the kept band. The fast forms of the
same filters are compared with these in ``tests/accel/test_fourier_filter.py``.
"""

from __future__ import annotations

import itertools
import math

import pytest
import torch
from hypothesis import given, settings
from hypothesis import strategies as st

from fourierf_plugin.field_components.fourier import (
    OFFICIAL_PLANE_LEAKAGE,
    filter_lines,
    filter_planes,
    kept_fraction_lines,
    kept_fraction_planes,
    line_mask,
    mirrored,
    plane_mask,
)

PLANE_SIZES = [(8, 8), (7, 7), (6, 9), (9, 6), (5, 12), (1, 4)]


def _rand(*shape: int, seed: int = 0) -> torch.Tensor:
    gen = torch.Generator().manual_seed(seed)
    return torch.randn(*shape, generator=gen, dtype=torch.float64)


def _energy(x: torch.Tensor) -> float:
    return float((x * x).sum())


def _reference_plane_filter(planes: torch.Tensor, f: float, leakage: float) -> torch.Tensor:
    """Spec 4.3 verbatim: disc centred at (H//2, W//2) on the fftshift-ed full spectrum, complex result."""
    height, width = planes.shape[-2:]
    rows = torch.arange(height, dtype=torch.float64)[:, None] - height // 2
    cols = torch.arange(width, dtype=torch.float64)[None, :] - width // 2
    dist = torch.sqrt(rows**2 + cols**2)
    rho = f * max(height, width) / math.sqrt(2.0)
    # +1e-9: points exactly on the circle are inside (dist <= rho) whatever the last bit of sqrt says.
    mask_full = (dist <= rho + 1e-9).to(torch.float64) + leakage
    shifted = torch.fft.fftshift(torch.fft.fft2(planes), dim=(-2, -1))
    return torch.fft.ifft2(torch.fft.ifftshift(shifted * mask_full, dim=(-2, -1)))


# ------------------------------------------------------------------------------------------------------- lines
def test_line_mask_shape_and_values() -> None:
    # L = 16: R = 9 bins. f = 0.3 -> c = 2.7: bins 0, 1 kept, bin 2 at 0.7, the rest exactly 0.
    mask = line_mask(16, 0.3, dtype=torch.float64)
    assert mask.shape == (9,)
    assert mask.tolist() == pytest.approx([1, 1, 0.7, 0, 0, 0, 0, 0, 0], abs=1e-12)
    assert (mask[3:] == 0).all()
    assert line_mask(16, 0.05).tolist() == [1.0] + [0.0] * 8  # c = 0.45 < 1: DC only
    assert line_mask(16, 1.0).tolist() == [1.0] * 9
    assert line_mask(15, 0.5).shape == (8,)


def test_line_f1_is_identity() -> None:
    x = _rand(3, 17)
    assert filter_lines(x, 1.0) is x


@pytest.mark.parametrize("length", [1, 2, 3, 7, 16, 33])
def test_line_f0_keeps_mean(length: int) -> None:
    x = _rand(4, length)
    out = filter_lines(x, 0.0)
    assert out.shape == x.shape
    torch.testing.assert_close(out, x.mean(dim=-1, keepdim=True).expand_as(x), atol=1e-12, rtol=0)


def test_line_length_one_and_two() -> None:
    x1 = _rand(2, 1)
    for f in (0.0, 0.4, 1.0):
        torch.testing.assert_close(filter_lines(x1, f), x1)
    x2 = torch.tensor([[1.0, 3.0]], dtype=torch.float64)
    # R = 2: f = 0.75 -> c = 1.5, the Nyquist bin (amplitude -1 around mean 2) is halved.
    torch.testing.assert_close(filter_lines(x2, 0.75), torch.tensor([[1.5, 2.5]], dtype=torch.float64))


@pytest.mark.parametrize("length", [5, 8, 16, 33])
def test_line_energy_monotone_in_f(length: int) -> None:
    x = _rand(3, length, seed=length)
    energies = [_energy(filter_lines(x, f / 200)) for f in range(201)]
    assert all(b >= a - 1e-12 for a, b in itertools.pairwise(energies))
    assert energies[-1] == pytest.approx(_energy(x))


@pytest.mark.parametrize("length", [2, 7, 8, 16, 33, 128])
def test_line_filter_continuous_across_bin_edges(length: int) -> None:
    x = _rand(2, length, seed=1)
    bins = length // 2 + 1
    for k in range(1, bins + 1):
        edge = k / bins
        below = filter_lines(x, edge - 1e-7)
        above = filter_lines(x, min(1.0, edge + 1e-7))
        assert (below - above).abs().max() < 1e-5, f"jump at bin edge {k}/{bins}"


def test_line_filter_constant_below_first_edge_for_128() -> None:
    x = _rand(1, 128)
    # Spec 4.2: with L = 128 lines stay constant until f = 1/65 ~ 0.0154.
    assert filter_lines(x, 0.0153).std() < 1e-12
    assert filter_lines(x, 0.0160).std() > 1e-6


def test_line_idempotent_when_mask_is_binary() -> None:
    x = _rand(3, 14)  # R = 8
    once = filter_lines(x, 0.5)  # c = 4 exactly: binary mask, a projection
    torch.testing.assert_close(filter_lines(once, 0.5), once, atol=1e-12, rtol=0)


def test_line_not_idempotent_with_fractional_edge_bin() -> None:
    # c = 8 * 0.3 = 2.4: bin 2 is weighted 0.4, so a second pass scales it by 0.4^2 instead of 0.4. This is why the
    # model filters the raw parameters each step rather than re-filtering filtered ones.
    x = _rand(3, 14)
    spec_x = torch.fft.rfft(x)
    spec_once = torch.fft.rfft(filter_lines(x, 0.3))
    spec_twice = torch.fft.rfft(filter_lines(filter_lines(x, 0.3), 0.3))
    torch.testing.assert_close(spec_once[..., :2], spec_x[..., :2])
    torch.testing.assert_close(spec_once[..., 2], 0.4 * spec_x[..., 2])
    torch.testing.assert_close(spec_twice[..., 2], 0.4**2 * spec_x[..., 2])
    assert spec_twice[..., 3:].abs().max() < 1e-12


def test_line_batched_shapes_and_float32() -> None:
    x = _rand(1, 4, 9).float()
    out = filter_lines(x, 0.37)
    assert out.shape == x.shape and out.dtype == torch.float32
    torch.testing.assert_close(out[0, 2], filter_lines(x[0, 2], 0.37))


def test_line_half_precision_round_trips_dtype() -> None:
    x = _rand(2, 10).to(torch.bfloat16)
    out = filter_lines(x, 0.4)
    assert out.dtype == torch.bfloat16
    torch.testing.assert_close(out.float(), filter_lines(x.float(), 0.4), atol=1e-2, rtol=1e-2)


def test_line_filter_wraps_periodically() -> None:
    # Spec 7.7: the filter is circular, so an impulse on one border leaks equally onto the opposite border.
    x = torch.zeros(32, dtype=torch.float64)
    x[0] = 1.0
    out = filter_lines(x, 0.3)
    assert out[-1] == pytest.approx(float(out[1]), abs=1e-12)
    assert abs(float(out[-1])) > 1e-3


# ------------------------------------------------------------------------------------------------------ planes
@pytest.mark.parametrize(("height", "width"), PLANE_SIZES)
@pytest.mark.parametrize("leakage", [0.0, OFFICIAL_PLANE_LEAKAGE])
def test_plane_filter_matches_shifted_reference(height: int, width: int, leakage: float) -> None:
    planes = _rand(3, height, width, seed=height * 31 + width)
    for f in (0.0, 0.13, 0.3, 0.5, 0.62, 0.7071, 0.85, 0.97):
        ref = _reference_plane_filter(planes, f, leakage)
        assert ref.imag.abs().max() < 1e-5  # the disc is symmetric, so the reference is real too
        out = filter_planes(planes, f, leakage)
        assert out.shape == planes.shape and not out.is_complex()
        torch.testing.assert_close(out, ref.real, atol=1e-10, rtol=0, msg=f"f={f} size={(height, width)}")


@pytest.mark.parametrize(("height", "width"), PLANE_SIZES)
def test_plane_mask_is_unshifted_half_of_centred_disc(height: int, width: int) -> None:
    f, leakage = 0.55, 1e-3
    rows = torch.arange(height, dtype=torch.float64)[:, None] - height // 2
    cols = torch.arange(width, dtype=torch.float64)[None, :] - width // 2
    rho = f * max(height, width) / math.sqrt(2.0)
    centred = (torch.sqrt(rows**2 + cols**2) <= rho + 1e-9).to(torch.float64) + leakage
    expected = torch.fft.ifftshift(centred, dim=(-2, -1))[:, : width // 2 + 1]
    torch.testing.assert_close(plane_mask(height, width, f, leakage, dtype=torch.float64), expected)


def test_plane_f1_identity_and_leakage_scaling() -> None:
    planes = _rand(2, 6, 9)
    assert filter_planes(planes, 1.0) is planes
    torch.testing.assert_close(filter_planes(planes, 1.0, 1e-6), planes * (1 + 1e-6), atol=0, rtol=0)
    assert plane_mask(6, 9, 1.0).eq(1.0).all()


@pytest.mark.parametrize(("height", "width"), PLANE_SIZES)
def test_plane_f0_keeps_mean(height: int, width: int) -> None:
    planes = _rand(1, 3, height, width)
    mean = planes.mean(dim=(-2, -1), keepdim=True)
    torch.testing.assert_close(filter_planes(planes, 0.0), mean.expand_as(planes), atol=1e-12, rtol=0)
    # With leakage l every coefficient keeps l of itself and DC gets 1 + l: mean + l * P, i.e. the spec's
    # "mean + 1e-6 (P - mean)" plus the l * mean it rounds away.
    leak = 1e-6
    torch.testing.assert_close(filter_planes(planes, 0.0, leak), mean + leak * planes, atol=1e-12, rtol=0)
    torch.testing.assert_close(filter_planes(planes, 0.0, leak), mean + leak * (planes - mean), atol=1e-5, rtol=0)


def test_plane_small_f_on_128_keeps_dc_only() -> None:
    # Spec 4.3: at f = 0.01 on 128^2, rho = 0.905 < 1, so only DC survives.
    planes = _rand(2, 128, 128)
    out = filter_planes(planes, 0.01)
    torch.testing.assert_close(out, planes.mean(dim=(-2, -1), keepdim=True).expand_as(planes), atol=1e-12, rtol=0)


@pytest.mark.parametrize(("height", "width"), PLANE_SIZES)
def test_plane_idempotent_without_leakage(height: int, width: int) -> None:
    planes = _rand(2, height, width)
    once = filter_planes(planes, 0.4)
    torch.testing.assert_close(filter_planes(once, 0.4), once, atol=1e-12, rtol=0)


def test_plane_energy_monotone_in_f() -> None:
    planes = _rand(2, 9, 14)
    for leakage in (0.0, OFFICIAL_PLANE_LEAKAGE):
        energies = [_energy(filter_planes(planes, f / 150, leakage)) for f in range(151)]
        assert all(b >= a - 1e-12 for a, b in itertools.pairwise(energies))


def test_plane_boundary_points_are_inside() -> None:
    # f = 0.5 on 8x8: rho^2 = 8 exactly, so (2, 2) lies on the circle and must be kept (dist <= rho).
    mask = plane_mask(8, 8, 0.5, dtype=torch.float64)
    assert mask[2, 2] == 1.0 and mask[-2, 2] == 1.0
    assert mask[3, 2] == 0.0


def test_plane_filter_wraps_periodically() -> None:
    plane = torch.zeros(16, 16, dtype=torch.float64)
    plane[0, 5] = 1.0
    out = filter_planes(plane, 0.3)
    assert out[-1, 5] == pytest.approx(float(out[1, 5]), abs=1e-12)
    assert abs(float(out[-1, 5])) > 1e-3


# --------------------------------------------------------------------------------------------- mirror boundary
def test_mirror_boundary_does_not_wrap() -> None:
    # The periodic filter puts an impulse on one face onto the opposite one; the mirror one keeps it on its side.
    x = torch.zeros(32, dtype=torch.float64)
    x[0] = 1.0
    out = mirrored(filter_lines, x, 0.3, 1)
    assert abs(float(out[-1])) < 0.1 * abs(float(filter_lines(x, 0.3)[-1]))
    assert float(out[0]) > float(filter_lines(x, 0.3)[0])  # the impulse's mass stays at its own face
    plane = torch.zeros(16, 16, dtype=torch.float64)
    plane[0, 5] = 1.0
    out = mirrored(filter_planes, plane, 0.3, 2, 0.0)
    assert abs(float(out[-1, 5])) < 0.1 * abs(float(filter_planes(plane, 0.3)[-1, 5]))


def test_mirror_boundary_identity_at_f1_and_mean_at_f0() -> None:
    lines, planes = _rand(3, 17), _rand(2, 6, 9, seed=1)
    assert mirrored(filter_lines, lines, 1.0, 1) is lines
    torch.testing.assert_close(mirrored(filter_planes, planes, 1.0, 2, 0.0), planes)
    torch.testing.assert_close(
        mirrored(filter_lines, lines, 0.0, 1), lines.mean(dim=-1, keepdim=True).expand_as(lines), atol=1e-12, rtol=0
    )
    mean = planes.mean(dim=(-2, -1), keepdim=True).expand_as(planes)
    torch.testing.assert_close(mirrored(filter_planes, planes, 0.0, 2, 0.0), mean, atol=1e-12, rtol=0)


@pytest.mark.parametrize(("height", "width"), [(8, 8), (7, 10)])
def test_mirror_boundary_is_self_adjoint_and_keeps_constants(height: int, width: int) -> None:
    # Self-adjoint, so the fast filters' backward (the same filter on the gradient) stays exact under mirroring.
    x, y = _rand(2, height, width, seed=2), _rand(2, height, width, seed=3)
    filt = lambda p: mirrored(filter_planes, p, 0.35, 2, 0.0)  # noqa: E731
    assert float((filt(x) * y).sum()) == pytest.approx(float((x * filt(y)).sum()), abs=1e-10)
    ones = torch.ones(height, width, dtype=torch.float64)
    torch.testing.assert_close(filt(ones), ones)
    line = _rand(1, 2, height, seed=4)
    line_filt = lambda v: mirrored(filter_lines, v, 0.35, 1)  # noqa: E731
    assert float((line_filt(line) * line.flip(-1)).sum()) == pytest.approx(
        float((line * line_filt(line.flip(-1))).sum()), abs=1e-10
    )


# ------------------------------------------------------------------------------------------------ shared checks
def test_gradients_are_finite() -> None:
    lines = _rand(4, 33).float().requires_grad_()
    planes = _rand(1, 4, 12, 7).float().requires_grad_()
    loss = (filter_lines(lines, 0.3) ** 2).sum() + (filter_planes(planes, 0.3, 1e-6) ** 2).sum()
    loss.backward()
    for grad in (lines.grad, planes.grad):
        assert grad is not None and torch.isfinite(grad).all() and grad.abs().sum() > 0
    # The identity shortcut keeps the graph: d/dx sum(x^2) = 2x.
    x = _rand(3, 8).requires_grad_()
    (filter_lines(x, 1.0) ** 2).sum().backward()
    torch.testing.assert_close(x.grad, 2 * x.detach())


def test_gradient_of_filtered_loss_is_band_limited() -> None:
    # Out-of-band parameters get no gradient: the filter is a projection and its adjoint is itself.
    x = _rand(2, 16).requires_grad_()
    (filter_lines(x, 0.25) * _rand(2, 16, seed=5)).sum().backward()
    assert torch.fft.rfft(x.grad)[..., 3:].abs().max() < 1e-12  # c = 9 * 0.25 = 2.25: bins >= 3 are zero


def test_mask_cache_returns_shared_equal_tensors() -> None:
    assert line_mask(16, 0.3) is line_mask(16, 0.3)
    assert plane_mask(6, 9, 0.4, 1e-6) is plane_mask(6, 9, 0.4, 1e-6)
    torch.testing.assert_close(line_mask(16, 0.3, device="cpu"), line_mask(16, 0.3))
    assert line_mask(16, 0.3, dtype=torch.float64).dtype == torch.float64
    assert line_mask(16, 0.3).dtype == torch.float32


@pytest.mark.parametrize("bad", [-0.1, 1.0000001, 2.0, float("nan"), float("inf"), "x"])
def test_invalid_cutoff_raises(bad: object) -> None:
    x = _rand(2, 8, 8)
    with pytest.raises(ValueError, match="cutoff"):
        filter_lines(x, bad)  # type: ignore[arg-type]
    with pytest.raises(ValueError, match="cutoff"):
        filter_planes(x, bad)  # type: ignore[arg-type]
    with pytest.raises(ValueError, match="cutoff"):
        line_mask(8, bad)  # type: ignore[arg-type]
    with pytest.raises(ValueError, match="cutoff"):
        plane_mask(8, 8, bad)  # type: ignore[arg-type]


def test_invalid_leakage_and_shapes_raise() -> None:
    with pytest.raises(ValueError, match="leakage"):
        filter_planes(_rand(4, 4), 0.5, -1e-6)
    with pytest.raises(ValueError, match="at least 2 dims"):
        filter_planes(_rand(4), 0.5)
    with pytest.raises(ValueError, match="line length"):
        line_mask(0, 0.5)


def test_kept_fractions() -> None:
    assert kept_fraction_planes(128, 128, 0.3) == pytest.approx(math.pi * 0.3**2 / 2, rel=0.02)
    assert kept_fraction_planes(128, 128, 0.01) == pytest.approx(1 / 128**2)
    assert kept_fraction_planes(6, 9, 1.0) == 1.0
    assert kept_fraction_lines(128, 0.3) == pytest.approx(0.3, abs=0.02)
    assert kept_fraction_lines(128, 1.0) == 1.0
    assert kept_fraction_lines(7, 1.0) == 1.0
    assert kept_fraction_lines(128, 0.0) == pytest.approx(1 / 128)


# ------------------------------------------------------------------------------------------------- hypothesis
@settings(max_examples=40, deadline=None)
@given(
    height=st.integers(1, 12),
    width=st.integers(1, 12),
    f_pair=st.tuples(st.floats(0.0, 1.0), st.floats(0.0, 1.0)),
    leakage=st.sampled_from([0.0, 1e-6, 0.1]),
    seed=st.integers(0, 2**16),
)
def test_plane_energy_monotone_and_contractive(
    height: int, width: int, f_pair: tuple[float, float], leakage: float, seed: int
) -> None:
    planes = _rand(2, height, width, seed=seed)
    f_lo, f_hi = sorted(f_pair)
    e_lo = _energy(filter_planes(planes, f_lo, leakage))
    e_hi = _energy(filter_planes(planes, f_hi, leakage))
    assert e_lo <= e_hi + 1e-9
    if leakage == 0.0:
        assert e_hi <= _energy(planes) + 1e-9


@settings(max_examples=40, deadline=None)
@given(
    length=st.integers(1, 40),
    f_pair=st.tuples(st.floats(0.0, 1.0), st.floats(0.0, 1.0)),
    seed=st.integers(0, 2**16),
)
def test_line_energy_monotone_and_contractive(length: int, f_pair: tuple[float, float], seed: int) -> None:
    lines = _rand(3, length, seed=seed)
    f_lo, f_hi = sorted(f_pair)
    e_lo = _energy(filter_lines(lines, f_lo))
    e_hi = _energy(filter_lines(lines, f_hi))
    assert e_lo <= e_hi + 1e-9 <= _energy(lines) + 2e-9
