"""The appearance decoder and its degree-2 real spherical harmonics (spec 3.5)."""

from __future__ import annotations

import math

import pytest
import torch

from fourierf_plugin.field_components.decoder import AppearanceDecoder, spherical_harmonics_deg2


def _fibonacci_sphere(n: int) -> torch.Tensor:
    """Deterministic, near-uniform unit vectors [n, 3] (equal-area points; quadrature error ~1/n)."""
    k = torch.arange(n, dtype=torch.float64) + 0.5
    z = 1.0 - 2.0 * k / n
    r = torch.sqrt(1.0 - z * z)
    phi = math.pi * (3.0 - math.sqrt(5.0)) * k
    return torch.stack([r * torch.cos(phi), r * torch.sin(phi), z], dim=-1)


def _closed_form(x: float, y: float, z: float) -> list[float]:
    """Real SH up to l = 2 in the TensoRF/plenoxels sign convention, written out from the textbook constants."""
    c0 = 0.5 * math.sqrt(1.0 / math.pi)
    c1 = math.sqrt(3.0 / (4.0 * math.pi))
    c2a = 0.5 * math.sqrt(15.0 / math.pi)
    c2b = 0.25 * math.sqrt(5.0 / math.pi)
    c2c = 0.25 * math.sqrt(15.0 / math.pi)
    return [
        c0,
        -c1 * y,
        c1 * z,
        -c1 * x,
        c2a * x * y,
        -c2a * y * z,
        c2b * (3 * z * z - 1),
        -c2a * x * z,
        c2c * (x * x - y * y),
    ]


@pytest.mark.parametrize(
    "d", [(1, 0, 0), (-1, 0, 0), (0, 1, 0), (0, -1, 0), (0, 0, 1), (0, 0, -1), (0.6, 0.0, 0.8), (0.48, 0.6, 0.64)]
)
def test_sh_matches_closed_form(d: tuple[float, float, float]) -> None:
    out = spherical_harmonics_deg2(torch.tensor([d], dtype=torch.float64))
    assert out.shape == (1, 9)
    assert out[0].tolist() == pytest.approx(_closed_form(*d), abs=1e-12)


def test_sh_axis_values_explicit() -> None:
    out = spherical_harmonics_deg2(torch.eye(3, dtype=torch.float64))
    c0, c1 = 0.28209479177387814, 0.4886025119029199
    # +x: Y_3 = -c1, Y_6 = -c2b, Y_8 = c2c; +z: Y_2 = c1, Y_6 = 2 c2b.
    assert out[0].tolist() == pytest.approx([c0, 0, 0, -c1, 0, 0, -0.31539156525252005, 0, 0.5462742152960396])
    assert out[2].tolist() == pytest.approx([c0, 0, c1, 0, 0, 0, 2 * 0.31539156525252005, 0, 0])


def test_sh_orthonormal_on_sphere() -> None:
    """(4π/n) Σ Y_i Y_j ≈ δ_ij on a Fibonacci sphere (the basis is orthonormal w.r.t. the area measure)."""
    d = _fibonacci_sphere(20000)
    y = spherical_harmonics_deg2(d)
    gram = 4.0 * math.pi * (y.T @ y) / d.shape[0]
    torch.testing.assert_close(gram, torch.eye(9, dtype=torch.float64), atol=1e-3, rtol=0)


def test_sh_keeps_dtype_and_batch_shape() -> None:
    d = torch.nn.functional.normalize(torch.randn(4, 5, 3), dim=-1)
    out = spherical_harmonics_deg2(d)
    assert out.shape == (4, 5, 9) and out.dtype == torch.float32


def test_view_independent_decoder_has_no_view_layer_and_ignores_directions() -> None:
    torch.manual_seed(0)
    dec = AppearanceDecoder(27, 128, view_dependent=False)
    assert not dec.view_dependent and dec.view_layer is None
    assert sum(p.numel() for p in dec.parameters()) == 27 * 128 + 128 + 128 * 3 + 3
    feats = torch.randn(50, 27)
    base = dec(feats)
    dirs = torch.nn.functional.normalize(torch.randn(50, 3), dim=-1)
    assert torch.equal(dec(feats, dirs), base)
    assert torch.equal(dec(feats, -dirs), base)


def test_view_dependent_decoder_matches_spec_and_uses_directions() -> None:
    torch.manual_seed(0)
    dec = AppearanceDecoder(27, 128, view_dependent=True)
    assert dec.view_dependent
    assert sum(p.numel() for p in dec.parameters()) == 5251  # spec 3.5: MLP_Fea_No_View_Dependence
    feats = torch.randn(50, 27)
    dirs = torch.nn.functional.normalize(torch.randn(50, 3), dim=-1)
    out = dec(feats, dirs)
    h = dec.feature_layer(torch.nn.functional.silu(feats)) + dec.view_layer(spherical_harmonics_deg2(dirs))
    expected = torch.sigmoid(dec.output_layer(torch.nn.functional.silu(h)))
    torch.testing.assert_close(out, expected)
    assert not torch.allclose(dec(feats, -dirs), out)
    with pytest.raises(ValueError, match="directions"):
        dec(feats)


@pytest.mark.parametrize("view_dependent", [False, True])
def test_decoder_output_in_unit_interval_and_gradients_finite(view_dependent: bool) -> None:
    torch.manual_seed(0)
    dec = AppearanceDecoder(8, 16, view_dependent=view_dependent)
    feats = (torch.randn(64, 8) * 100).requires_grad_()
    dirs = torch.nn.functional.normalize(torch.randn(64, 3), dim=-1)
    out = dec(feats, dirs)
    assert out.shape == (64, 3)
    assert ((out >= 0) & (out <= 1)).all()
    small = dec(torch.randn(64, 8), dirs)
    assert ((small > 0) & (small < 1)).all()
    out.sum().backward()
    assert torch.isfinite(feats.grad).all()
    assert all(torch.isfinite(p.grad).all() for p in dec.parameters())
