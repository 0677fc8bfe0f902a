"""Property tests (hypothesis) for the reference Fourier masks and filters (``field_components.fourier``).

test_fourier.py checks chosen shapes and cutoffs; here the properties are stated for any shape, cutoff and batch:
masks are low-pass and nested in f, filtering is a projection, f = 1 is the identity and f = 0 keeps the mean.
The compositing properties on the sampler's rays are in ``tests/model_components/test_rendering_properties.py``.
"""

from __future__ import annotations

import math

import torch
from hypothesis import given, settings
from hypothesis import strategies as st

from fourierf_plugin.field_components.fourier import filter_lines, filter_planes, line_mask, plane_mask

PROPERTY = settings(max_examples=40, deadline=None)
sizes = st.integers(1, 13)
cutoffs = st.floats(0.0, 1.0, allow_nan=False)
seeds = st.integers(0, 2**16)
leakages = st.sampled_from([0.0, 1e-6, 0.05])


def randn(*shape: int, seed: int) -> torch.Tensor:
    return torch.randn(*shape, generator=torch.Generator().manual_seed(seed), dtype=torch.float64)


def broadcast_mean(x: torch.Tensor, dims: tuple[int, ...]) -> torch.Tensor:
    return x.mean(dim=dims, keepdim=True).expand_as(x)


# -- masks ----------------------------------------------------------------------------------------------------------
@PROPERTY
@given(length=sizes, f_pair=st.tuples(cutoffs, cutoffs))
def test_line_mask_is_a_low_pass_nested_in_f(length: int, f_pair: tuple[float, float]) -> None:
    """Weights in [0, 1], DC always 1, never increasing with frequency, and pointwise non-decreasing in f."""
    lo, hi = sorted(f_pair)
    m_lo = line_mask(length, lo, dtype=torch.float64)
    m_hi = line_mask(length, hi, dtype=torch.float64)
    for m in (m_lo, m_hi):
        assert m.shape == (length // 2 + 1,)
        assert bool(((m >= 0) & (m <= 1)).all()) and float(m[0]) == 1.0
        assert bool((m[1:] <= m[:-1]).all())
    assert bool((m_lo <= m_hi).all())


@PROPERTY
@given(height=sizes, width=sizes, f_pair=st.tuples(cutoffs, cutoffs), leakage=leakages)
def test_plane_mask_is_a_disc_nested_in_f(height: int, width: int, f_pair: tuple[float, float], leakage: float) -> None:
    """Entries are 1 (+ leakage) inside and leakage outside; DC is in; the disc only grows with f."""
    lo, hi = sorted(f_pair)
    m_lo = plane_mask(height, width, lo, leakage, dtype=torch.float64)
    m_hi = plane_mask(height, width, hi, leakage, dtype=torch.float64)
    for m in (m_lo, m_hi):
        assert m.shape == (height, width // 2 + 1)
        inside = (m - leakage).round()
        assert bool(((inside == 0) | (inside == 1)).all()) and float(inside[0, 0]) == 1.0
    assert bool((m_lo <= m_hi).all())


# -- filters --------------------------------------------------------------------------------------------------------
@PROPERTY
@given(length=sizes, seed=seeds, data=st.data())
def test_line_filtering_is_idempotent_where_the_mask_is_binary(length: int, seed: int, data: st.DataObject) -> None:
    """At f = k / bins the mask is 0/1 and filtering is a projection; at any f a second pass only touches the one
    fractional edge bin (scaled by its weight again), never anything else."""
    bins = length // 2 + 1
    x = randn(3, length, seed=seed)
    k = data.draw(st.integers(0, bins), label="k")
    once = filter_lines(x, k / bins)
    torch.testing.assert_close(filter_lines(once, k / bins), once, atol=1e-12, rtol=0)

    f = data.draw(cutoffs, label="f")
    once, twice = filter_lines(x, f), filter_lines(filter_lines(x, f), f)
    mask = line_mask(length, f, dtype=torch.float64)
    torch.testing.assert_close(torch.fft.rfft(twice), torch.fft.rfft(x) * mask * mask, atol=1e-10, rtol=0)
    torch.testing.assert_close(torch.fft.rfft(once), torch.fft.rfft(x) * mask, atol=1e-10, rtol=0)


@PROPERTY
@given(height=sizes, width=sizes, f=cutoffs, seed=seeds)
def test_plane_filtering_is_idempotent_at_fixed_f(height: int, width: int, f: float, seed: int) -> None:
    x = randn(2, height, width, seed=seed)
    once = filter_planes(x, f)
    torch.testing.assert_close(filter_planes(once, f), once, atol=1e-12, rtol=0)


@PROPERTY
@given(height=sizes, width=sizes, f_pair=st.tuples(cutoffs, cutoffs), leakage=leakages, seed=seeds)
def test_filtered_spectrum_and_energy_grow_with_f(
    height: int, width: int, f_pair: tuple[float, float], leakage: float, seed: int
) -> None:
    """Every coefficient's magnitude (hence the energy) is non-decreasing in f, for lines and planes."""
    lo, hi = sorted(f_pair)
    planes = randn(2, height, width, seed=seed)
    lines = randn(2, width, seed=seed + 1)
    for lo_out, hi_out, dims in (
        (filter_planes(planes, lo, leakage), filter_planes(planes, hi, leakage), (-2, -1)),
        (filter_lines(lines, lo), filter_lines(lines, hi), (-1,)),
    ):
        spec_lo, spec_hi = torch.fft.rfftn(lo_out, dim=dims).abs(), torch.fft.rfftn(hi_out, dim=dims).abs()
        assert bool((spec_lo <= spec_hi + 1e-9).all())
        assert float(lo_out.pow(2).sum()) <= float(hi_out.pow(2).sum()) + 1e-9


@PROPERTY
@given(height=sizes, width=sizes, leakage=leakages, seed=seeds)
def test_f1_is_the_identity_for_any_shape(height: int, width: int, leakage: float, seed: int) -> None:
    """f = 1 returns the very tensor (no FFT round trip); with leakage, the official ``1 + leakage`` scaling."""
    planes, lines = randn(2, height, width, seed=seed), randn(2, width, seed=seed)
    assert filter_lines(lines, 1.0) is lines
    if leakage == 0.0:
        assert filter_planes(planes, 1.0) is planes
    else:
        torch.testing.assert_close(filter_planes(planes, 1.0, leakage), planes * (1.0 + leakage))


@PROPERTY
@given(height=sizes, width=sizes, seed=seeds, below=st.floats(0.0, 0.999))
def test_f0_and_any_f_below_the_first_ring_keep_only_the_mean(height: int, width: int, seed: int, below: float) -> None:
    """f = 0 keeps DC only: the output is the mean everywhere. So does any f below the first bin / ring."""
    planes, lines = randn(2, height, width, seed=seed), randn(3, width, seed=seed)
    first_line = 1.0 / (width // 2 + 1)  # c = bins · f reaches 1
    first_ring = math.sqrt(2.0) / max(height, width)  # ρ = f · max(H, W) / √2 reaches 1
    for f in (0.0, below * first_line):
        torch.testing.assert_close(filter_lines(lines, f), broadcast_mean(lines, (-1,)), atol=1e-12, rtol=0)
    for f in (0.0, min(1.0, below * first_ring)):
        torch.testing.assert_close(filter_planes(planes, f), broadcast_mean(planes, (-2, -1)), atol=1e-12, rtol=0)


@PROPERTY
@given(height=sizes, width=sizes, f=cutoffs, seed=seeds)
def test_every_cutoff_preserves_the_mean(height: int, width: int, f: float, seed: int) -> None:
    """DC is always kept: the low-pass never shifts the average density or colour feature."""
    planes, lines = randn(2, height, width, seed=seed), randn(3, height, seed=seed)
    torch.testing.assert_close(filter_planes(planes, f).mean(dim=(-2, -1)), planes.mean(dim=(-2, -1)))
    torch.testing.assert_close(filter_lines(lines, f).mean(dim=-1), lines.mean(dim=-1))
