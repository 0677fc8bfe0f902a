"""Property tests (hypothesis) for compositing along the sampler's real ray layout.

test_rendering.py checks single rays; here the properties are stated for any batch of rays laid out as the model
lays them out: compositing weights are bounded, the transmittance never increases, and a ray split in two
composites like the whole ray.
"""

from __future__ import annotations

import torch
from hypothesis import given, settings
from hypothesis import strategies as st

from fourierf_plugin.model_components.ray_sampling import ray_box_span, sample_deltas, step_samples
from fourierf_plugin.model_components.rendering import (
    blend_background,
    composite_weights,
    expected_depth,
)
from tests.helpers import accumulate_rays

PROPERTY = settings(max_examples=40, deadline=None)
seeds = st.integers(0, 2**16)


# -- compositing on the sampler's rays ------------------------------------------------------------------------------
BOX = torch.tensor([[-1.5, -1.5, -1.5], [1.5, 1.5, 1.5]], dtype=torch.float64)
NEAR, FAR, STEP = 2.0, 6.0, 0.1


def sampler_rays(seed: int, num_rays: int, num_samples: int) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """The model's euclidean layout: rays from a shell around the box, fixed steps from the box entry, jitter.

    Returns t, δ [R, N] and the in-box mask (σ is zero past the exit, as the model's ``inside`` test makes it).
    """
    gen = torch.Generator().manual_seed(seed)
    origins = torch.nn.functional.normalize(torch.randn(num_rays, 3, generator=gen, dtype=torch.float64), dim=-1) * 4
    targets = (torch.rand(num_rays, 3, generator=gen, dtype=torch.float64) - 0.5) * 4.0  # some rays miss the box
    directions = torch.nn.functional.normalize(targets - origins, dim=-1)
    start, t_exit = ray_box_span(origins, directions, BOX, NEAR, FAR)
    t = step_samples(start, STEP, num_samples, torch.rand(num_rays, generator=gen, dtype=torch.float64))
    return t, sample_deltas(t), t < t_exit.unsqueeze(-1)


def densities(seed: int, zero_share: float, log10_max: float) -> torch.Tensor:
    """σ [8, 64]: log-uniform over six decades up to 10^log10_max, with a share of exact zeros (empty space)."""
    gen = torch.Generator().manual_seed(seed + 7)
    sigma = 10 ** (log10_max - 6 * torch.rand(8, 64, generator=gen, dtype=torch.float64))
    return sigma * (torch.rand(8, 64, generator=gen, dtype=torch.float64) >= zero_share)


zero_shares = st.sampled_from([0.0, 0.5, 0.9, 1.0])
density_peaks = st.floats(-2.0, 4.0)  # up to σ = 1e4


@PROPERTY
@given(
    seed=seeds,
    zeros=zero_shares,
    peak=density_peaks,
    scale=st.sampled_from([1.0, 25.0]),
    dtype=st.sampled_from(["float32", "float64"]),
)
def test_weights_bounded_and_transmittance_monotone_on_sampler_rays(
    seed: int, zeros: float, peak: float, scale: float, dtype: str
) -> None:
    """w ∈ [0, 1], Σw = 1 - exp(-Στ) ≤ 1, T_k = exp(-Σ_{j<k} τ_j) non-increasing, composite colour and depth
    bounded; in float32 and float64 on rays laid out exactly as the model lays them out."""
    t, deltas, inside = sampler_rays(seed, 8, 64)
    dt = getattr(torch, dtype)
    s = densities(seed, zeros, peak) * inside
    w = composite_weights(s.to(dt), deltas.to(dt), scale).double()
    tau = s * deltas * scale
    assert bool(torch.isfinite(w).all()) and bool(((w >= 0) & (w <= 1)).all())
    acc = w.sum(dim=-1)
    assert bool((acc <= 1.0 + 1e-6).all())
    torch.testing.assert_close(acc, -torch.expm1(-tau.sum(dim=-1)), atol=1e-5, rtol=0)
    prefix = torch.cumsum(w, dim=-1)  # 1 - prefix is T_{k+1}: non-increasing and within [0, 1]
    assert bool((prefix[:, 1:] >= prefix[:, :-1] - 1e-12).all()) and bool((prefix <= 1.0 + 1e-6).all())

    gen = torch.Generator().manual_seed(seed)
    colors, background = torch.rand(8, 64, 3, generator=gen).double(), torch.rand(8, 3, generator=gen).double()
    rgb = blend_background(accumulate_rays(w, colors), acc, background)
    assert bool(((rgb >= -1e-6) & (rgb <= 1.0 + 1e-6)).all())
    depth = expected_depth(w, t, torch.full_like(acc, FAR))
    assert bool((depth >= t[:, 0].clamp(max=FAR) - 1e-6).all()) and bool(
        (depth <= torch.maximum(t[:, -1], torch.tensor(FAR))).all()
    )


@PROPERTY
@given(seed=seeds, zeros=zero_shares, peak=density_peaks, split=st.integers(1, 63))
def test_a_ray_split_in_two_composites_like_the_whole_ray(seed: int, zeros: float, peak: float, split: int) -> None:
    """w(a ++ b) = w(a) ++ T(a) · w(b) with T(a) = exp(-Σ τ_a): compositing is a semigroup along the ray, so
    samples past the exit (σ = 0) or another ray's extra samples change nothing before them."""
    _, deltas, inside = sampler_rays(seed, 8, 64)
    s = densities(seed, zeros, peak) * inside
    whole = composite_weights(s, deltas, 25.0)
    head = composite_weights(s[:, :split], deltas[:, :split], 25.0)
    tail = composite_weights(s[:, split:], deltas[:, split:], 25.0)
    through = torch.exp(-(s[:, :split] * deltas[:, :split] * 25.0).sum(dim=-1, keepdim=True))
    torch.testing.assert_close(whole[:, :split], head, atol=1e-12, rtol=0)
    torch.testing.assert_close(whole[:, split:], through * tail, atol=1e-12, rtol=1e-9)
