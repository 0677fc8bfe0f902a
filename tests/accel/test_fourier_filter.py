"""The accelerated Fourier low-pass (``accel.fourier_filter``) is the reference filter, faster.

Checked against ``field_components.fourier`` in float64: the outputs agree to ~1e-11 for planes of many sizes
(square, non-square, odd, 1-wide, fern's prime-sized NDC grids), cutoffs and leakages and for lines, whichever form
the cost model picks; the hand-written self-adjoint backward equals autograd through the reference's FFTs; the
matrix ("band") form is the same operator as the FFTs; the cost model sends small cutoffs and awkward sizes to the
matrices and wide bands on smooth sizes to the FFTs; and the backward is charged to its own profiler phase.
"""

from __future__ import annotations

import itertools
import re

import pytest
import torch

from fourierf_plugin.accel import fourier_filter
from fourierf_plugin.accel.fourier_filter import filter_lines, filter_planes
from fourierf_plugin.field_components import fourier
from fourierf_plugin.field_components.fourier import OFFICIAL_PLANE_LEAKAGE, plane_mask
from fourierf_plugin.utils.phases import PhaseTimer, phase

PLANE_SIZES = [(8, 8), (7, 7), (6, 9), (9, 6), (5, 12), (1, 4), (2, 1), (16, 32), (71, 79), (47, 16), (142, 94)]
CUTOFFS = [0.0, 0.05, 0.13, 0.3, 0.5, 0.62, 0.7071, 0.85, 0.97, 1.0]
LEAKAGES = [0.0, OFFICIAL_PLANE_LEAKAGE, 0.1]


def _rand(*shape: int, seed: int = 0) -> torch.Tensor:
    gen = torch.Generator().manual_seed(seed)
    return torch.randn(*shape, generator=gen, dtype=torch.float64)


def _fft_filter(planes: torch.Tensor, f: float, leakage: float) -> torch.Tensor:
    """``irfft2(rfft2(P) * mask)`` with autograd through the FFTs (no shortcut at f = 1)."""
    height, width = planes.shape[-2:]
    mask = plane_mask(height, width, f, leakage, dtype=torch.float64)
    return torch.fft.irfft2(torch.fft.rfft2(planes, dim=(-2, -1)) * mask, s=(height, width), dim=(-2, -1))


def _output_and_gradient(
    fn, x: torch.Tensor, upstream: torch.Tensor, *args: float
) -> tuple[torch.Tensor, torch.Tensor]:
    x = x.detach().clone().requires_grad_()
    out = fn(x, *args)
    (grad,) = torch.autograd.grad(out, x, upstream)
    return out.detach(), grad


# ---------------------------------------------------------------------------------------- parity with the reference
@pytest.mark.parametrize(("height", "width"), PLANE_SIZES)
@pytest.mark.parametrize("leakage", LEAKAGES)
def test_planes_equal_the_reference_filter_in_values_and_gradients(height: int, width: int, leakage: float) -> None:
    planes = _rand(2, height, width, seed=height + 7 * width)
    upstream = _rand(2, height, width, seed=height * width + 1)
    for f in CUTOFFS:
        ours, ours_grad = _output_and_gradient(filter_planes, planes, upstream, f, leakage)
        ref, ref_grad = _output_and_gradient(fourier.filter_planes, planes, upstream, f, leakage)
        msg = f"f={f} size={(height, width)} band={fourier_filter._prefer_band(height, width, f)}"
        assert ours.shape == planes.shape and ours.dtype == torch.float64
        torch.testing.assert_close(ours, ref, atol=1e-11, rtol=0, msg=msg)
        torch.testing.assert_close(ours_grad, ref_grad, atol=1e-11, rtol=0, msg=msg)


@pytest.mark.parametrize("length", [1, 2, 3, 7, 8, 16, 33, 128])
def test_lines_equal_the_reference_filter_in_values_and_gradients(length: int) -> None:
    lines = _rand(3, length, seed=length)
    upstream = _rand(3, length, seed=length + 1)
    for f in [*CUTOFFS, 0.21, 0.0153, 0.0160]:
        ours, ours_grad = _output_and_gradient(filter_lines, lines, upstream, f)
        ref, ref_grad = _output_and_gradient(fourier.filter_lines, lines, upstream, f)
        torch.testing.assert_close(ours, ref, atol=1e-11, rtol=0, msg=f"f={f} length={length}")
        torch.testing.assert_close(ours_grad, ref_grad, atol=1e-11, rtol=0, msg=f"f={f} length={length}")


def test_batched_planes_and_lines_in_the_models_layouts() -> None:
    planes, lines = _rand(1, 4, 12, 7), _rand(1, 4, 9)
    torch.testing.assert_close(filter_planes(planes, 0.3, 1e-6), fourier.filter_planes(planes, 0.3, 1e-6))
    torch.testing.assert_close(filter_lines(lines, 0.37), fourier.filter_lines(lines, 0.37))


def test_f1_is_the_identity_and_leakage_scales() -> None:
    planes, lines = _rand(2, 6, 9), _rand(3, 17)
    assert filter_planes(planes, 1.0) is planes
    assert filter_lines(lines, 1.0) is lines
    torch.testing.assert_close(filter_planes(planes, 1.0, 1e-6), planes * (1 + 1e-6), atol=0, rtol=0)
    x = lines.clone().requires_grad_()  # the identity keeps the graph: d/dx sum(x^2) = 2x
    (filter_lines(x, 1.0) ** 2).sum().backward()
    torch.testing.assert_close(x.grad, 2 * x.detach())


@pytest.mark.parametrize("dtype", [torch.float32, torch.bfloat16])
def test_low_precision_inputs_keep_their_dtype_and_the_reference_values(dtype: torch.dtype) -> None:
    planes, lines = _rand(2, 10, 12).to(dtype), _rand(2, 10).to(dtype)
    for f in (0.05, 0.4):  # the band form and the FFTs on a 10x12 plane
        out = filter_planes(planes, f)
        assert out.dtype == dtype
        torch.testing.assert_close(out, fourier.filter_planes(planes, f), atol=1e-5, rtol=1e-5)
    out = filter_lines(lines, 0.4)
    assert out.dtype == dtype
    torch.testing.assert_close(out, fourier.filter_lines(lines, 0.4), atol=1e-5, rtol=1e-5)


@pytest.mark.parametrize(
    ("name", "shape", "args"),
    [
        ("filter_lines", (2, 8), (-0.1,)),
        ("filter_lines", (2, 8), (float("nan"),)),
        ("filter_lines", (2, 8), ("x",)),
        ("filter_planes", (2, 8, 8), (1.0000001,)),
        ("filter_planes", (2, 8, 8), (0.5, -1e-6)),
        ("filter_planes", (8,), (0.5,)),
    ],
)
def test_invalid_arguments_raise_the_references_errors(name: str, shape: tuple[int, ...], args: tuple) -> None:
    x = _rand(*shape)
    with pytest.raises(ValueError) as expected:
        getattr(fourier, name)(x, *args)
    with pytest.raises(ValueError, match=re.escape(str(expected.value))):
        getattr(fourier_filter, name)(x, *args)


# ------------------------------------------------------------------------------------------- the self-adjoint backward
@pytest.mark.parametrize("shape", [(3, 7, 8), (2, 8, 8), (4, 9, 5), (2, 1, 5), (3, 16, 32), (2, 71, 79)])
@pytest.mark.parametrize("f", [0.0, 0.13, 0.5, 0.77])
@pytest.mark.parametrize("leakage", [0.0, 1e-6])
def test_plane_gradient_equals_autograd_through_the_ffts(shape: tuple[int, ...], f: float, leakage: float) -> None:
    """The hand-written backward (the filter applied to the gradient) is the exact adjoint of the forward."""
    x = torch.randn(shape, dtype=torch.float64, requires_grad=True)
    g = torch.randn(shape, dtype=torch.float64)
    (ours,) = torch.autograd.grad(filter_planes(x, f, leakage), x, g)
    (ref,) = torch.autograd.grad(_fft_filter(x, f, leakage), x, g)
    torch.testing.assert_close(ours, ref, atol=1e-11, rtol=0)


@pytest.mark.parametrize("length", [1, 2, 7, 8, 33])
@pytest.mark.parametrize("f", [0.0, 0.21, 0.5, 0.9])
def test_line_gradient_equals_autograd_through_the_ffts(length: int, f: float) -> None:
    x = torch.randn(3, length, dtype=torch.float64, requires_grad=True)
    g = torch.randn(3, length, dtype=torch.float64)
    (ours,) = torch.autograd.grad(filter_lines(x, f), x, g)
    mask = fourier.line_mask(length, f, dtype=torch.float64)
    (ref,) = torch.autograd.grad(torch.fft.irfft(torch.fft.rfft(x, dim=-1) * mask, n=length), x, g)
    torch.testing.assert_close(ours, ref, atol=1e-12, rtol=0)


@pytest.mark.parametrize("shape", [(4, 64, 64), (2, 71, 79)])  # the FFTs and the band form
def test_filter_backward_is_charged_to_its_own_phase(shape: tuple[int, ...]) -> None:
    x = torch.randn(shape, requires_grad=True)
    lines = torch.randn(4, 64, requires_grad=True)
    with PhaseTimer() as timer, phase("backward"):
        (filter_planes(x, 0.3).square().sum() + filter_lines(lines, 0.3).square().sum()).backward()
    assert set(timer.take()) == {"backward", "fourier_filter_backward"}
    with PhaseTimer() as timer, phase("backward"):  # the reference is plain autograd: nothing charged apart
        fourier.filter_planes(x, 0.3).square().sum().backward()
    assert set(timer.take()) == {"backward"}


# ------------------------------------------------------------------------------- plane filter: the matrix (band) form
@pytest.mark.parametrize(("height", "width"), PLANE_SIZES)
@pytest.mark.parametrize("f", [0.0, 0.05, 0.3, 0.62, 0.85, 0.97])
@pytest.mark.parametrize("leakage", [0.0, OFFICIAL_PLANE_LEAKAGE])
def test_band_form_equals_the_fft_filter(height: int, width: int, f: float, leakage: float) -> None:
    """Both implementations are the same operator, whichever one ``filter_planes`` picks for a shape."""
    planes = _rand(2, height, width, seed=height + 7 * width)
    operators = fourier_filter._band_operators(height, width, f, "cpu", torch.float64)
    ref = _fft_filter(planes, f, leakage)
    torch.testing.assert_close(fourier_filter._band_filter(planes, operators, leakage), ref, atol=1e-11, rtol=0)


def test_band_form_is_picked_for_small_cutoffs_and_awkward_sizes() -> None:
    """fern's NDC planes (prime factors 71, 79) take the matrices; a wide band on a 128² plane takes the FFTs."""
    slowdown = fourier_filter._fft_slowdown
    assert slowdown(142) == 4 and slowdown(128) == 1 and slowdown(94) == 2 and slowdown(7) == 1 and slowdown(1) == 1
    assert fourier_filter._prefer_band(142, 158, 0.05) and fourier_filter._prefer_band(142, 158, 0.3)
    assert fourier_filter._prefer_band(128, 128, 0.05)
    assert not fourier_filter._prefer_band(128, 128, 0.6)
    # The parity tests above run both forms.
    partial = [(h, w, f) for h, w in PLANE_SIZES for f in CUTOFFS if not fourier.plane_is_full(h, w, f)]
    assert {fourier_filter._prefer_band(*case) for case in partial} == {True, False}


def test_column_reach_is_the_disc_per_rfft_column() -> None:
    """Per column kw: the largest kept |kh| (capped at H/2), -1 where nothing is kept; never increasing in kw."""
    for height, width, f in [(8, 8, 0.5), (71, 79, 0.3), (6, 9, 0.62), (1, 4, 0.0)]:
        reach = fourier_filter._column_reach(height, width, f)
        mask = plane_mask(height, width, f, dtype=torch.float64)
        kh = fourier.signed_frequencies(height).abs()
        assert len(reach) == width // 2 + 1
        for kw, r in enumerate(reach):
            kept = kh[mask[:, kw] == 1.0]
            assert r == (int(kept.max()) if kept.numel() else -1)
        assert all(b <= a for a, b in itertools.pairwise(reach))


def test_band_form_filters_the_complement_once_whole_columns_are_kept() -> None:
    """Wide bands keep whole rfft columns; the matrices then work on the few columns that lose something."""
    assert fourier_filter._band_span(142, 158, 0.3) == (0, 34, False)  # direct: the columns kw <= rho = 33.5
    start, stop, complement = fourier_filter._band_span(142, 158, 0.8)  # rho = 89.4 > H/2 = 71: kw <= 54 keep all
    assert complement and (start, stop) == (55, 80)
    assert fourier_filter._band_span(71, 79, 0.85)[2]


def test_band_form_output_and_gradient_through_filter_planes() -> None:
    shape, f = (2, 71, 79), 0.3
    assert fourier_filter._prefer_band(71, 79, f)
    x = torch.randn(shape, dtype=torch.float64, requires_grad=True)
    g = torch.randn(shape, dtype=torch.float64)
    out = filter_planes(x, f, OFFICIAL_PLANE_LEAKAGE)
    ref_out = _fft_filter(x, f, OFFICIAL_PLANE_LEAKAGE)
    torch.testing.assert_close(out, ref_out, atol=1e-11, rtol=0)
    (ours,) = torch.autograd.grad(out, x, g)
    (ref,) = torch.autograd.grad(ref_out, x, g)
    torch.testing.assert_close(ours, ref, atol=1e-11, rtol=0)


def test_band_form_in_float32_stays_close_to_the_fft() -> None:
    planes = torch.randn(1, 16, 142, 94)
    assert fourier_filter._prefer_band(142, 94, 0.2)
    out = filter_planes(planes, 0.2)
    assert out.dtype == torch.float32
    torch.testing.assert_close(out.double(), _fft_filter(planes.double(), 0.2, 0.0), atol=2e-5, rtol=0)
