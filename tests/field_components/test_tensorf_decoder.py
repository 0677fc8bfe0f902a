"""TensoRF's colour decoder (``MLP_Fea``) against a reference written out from TensoRF's formulas, and the field that
reads through it with every grid-operations backend.

The reference: ``PE(x, F) = [sin(2^k x_d) for d, for k < F] ++ [cos(2^k x_d) for d, for k < F]`` (no π), the MLP input
``[a, d, PE(a, 2), PE(d, 2)]``, then Linear → ReLU → Linear → ReLU → Linear → sigmoid (apchenstu/TensoRF,
``models/tensorBase.py``: ``positional_encoding``, ``MLPRender_Fea``).
"""

from __future__ import annotations

import math

import pytest
import torch

from fourierf_plugin.accel import AccelConfig, AcceleratedOps
from fourierf_plugin.field_components.tensorf_decoder import TensoRFDecoder, frequency_encoding
from fourierf_plugin.fields.fourier_tensorf_field import FieldConfig, FourierTensoRFField
from fourierf_plugin.fields.grid_ops import GridOps


def reference_encoding(x: torch.Tensor, frequencies: int) -> torch.Tensor:
    """Column by column: every channel's sines at 2^0 .. 2^(F-1), channel after channel, then the cosines likewise."""
    columns = [torch.sin(2.0**k * x[:, d]) for d in range(x.shape[1]) for k in range(frequencies)]
    columns += [torch.cos(2.0**k * x[:, d]) for d in range(x.shape[1]) for k in range(frequencies)]
    return torch.stack(columns, dim=-1) if columns else x[:, :0]


def reference_decoder(
    weights: list[tuple[torch.Tensor, torch.Tensor]], features: torch.Tensor, directions: torch.Tensor, pe: tuple
) -> torch.Tensor:
    x = torch.cat(
        [features, directions, reference_encoding(features, pe[0]), reference_encoding(directions, pe[1])], -1
    )
    for i, (w, b) in enumerate(weights):
        x = x @ w.T + b
        if i < len(weights) - 1:
            x = torch.clamp(x, min=0.0)
    return 1.0 / (1.0 + torch.exp(-x))


def fixed_inputs(n: int = 64, dim: int = 27, seed: int = 7) -> tuple[torch.Tensor, torch.Tensor]:
    g = torch.Generator().manual_seed(seed)
    features = torch.randn(n, dim, generator=g, dtype=torch.float64) * 0.7
    directions = torch.nn.functional.normalize(torch.randn(n, 3, generator=g, dtype=torch.float64), dim=-1)
    return features, directions


def fixed_decoder(in_dim: int = 27, frequencies: tuple[int, int] = (2, 2)) -> TensoRFDecoder:
    """The decoder with weights drawn from a fixed generator (output bias included, so it is exercised)."""
    decoder = TensoRFDecoder(in_dim, 128, True, *frequencies).double()
    g = torch.Generator().manual_seed(11)
    with torch.no_grad():
        for p in decoder.parameters():
            p.copy_(torch.randn(p.shape, generator=g, dtype=torch.float64) / math.sqrt(p.shape[-1]))
    return decoder


def test_the_encoding_puts_each_channels_bands_together_and_the_cosines_after_the_sines() -> None:
    a, b = 0.3, -1.1
    expected = [math.sin(a), math.sin(2 * a), math.sin(b), math.sin(2 * b)]
    expected += [math.cos(a), math.cos(2 * a), math.cos(b), math.cos(2 * b)]
    got = frequency_encoding(torch.tensor([[a, b]], dtype=torch.float64), 2)
    assert torch.allclose(got, torch.tensor([expected], dtype=torch.float64), atol=1e-15)
    assert frequency_encoding(torch.ones(5, 3), 0).shape == (5, 0)


def test_the_input_widths_are_tensorfs() -> None:
    """150 inputs for a 27-wide feature at 2/2 (lego.txt), 30 at 0/0 (flower.txt); no direction without view
    dependence."""
    assert TensoRFDecoder(27, 128, True, 2, 2).mlp[0].in_features == 27 + 3 + 2 * 2 * 27 + 2 * 2 * 3 == 150
    assert TensoRFDecoder(27, 128, True, 0, 0).mlp[0].in_features == 30
    assert TensoRFDecoder(27, 128, False, 2, 2).mlp[0].in_features == 27 * 5
    decoder = TensoRFDecoder(27)
    assert [type(m).__name__ for m in decoder.mlp] == ["Linear", "ReLU", "Linear", "ReLU", "Linear"]
    assert decoder.mlp[2].in_features == decoder.mlp[2].out_features == 128 and decoder.mlp[4].out_features == 3
    assert torch.equal(decoder.mlp[4].bias, torch.zeros(3)), "TensoRF starts the output bias at 0"


@pytest.mark.parametrize("frequencies", [(2, 2), (0, 0), (3, 1)])
def test_the_decoder_equals_the_reference_on_fixed_inputs(frequencies: tuple[int, int]) -> None:
    decoder = fixed_decoder(27, frequencies)
    features, directions = fixed_inputs()
    weights = [(decoder.mlp[i].weight.detach(), decoder.mlp[i].bias.detach()) for i in (0, 2, 4)]
    expected = reference_decoder(weights, features, directions, frequencies)
    got = decoder(features, directions)
    assert got.shape == (64, 3)
    assert torch.allclose(got, expected, rtol=0, atol=1e-12)
    assert got.std().item() > 0.01, "the inputs reach the output (not a saturated sigmoid)"


def test_view_dependence_needs_directions_and_its_absence_ignores_them() -> None:
    features, directions = fixed_inputs(8)
    with pytest.raises(ValueError, match="directions"):
        fixed_decoder()(features)
    flat = TensoRFDecoder(27, 16, view_dependent=False).double()
    assert not flat.view_dependent
    assert torch.equal(flat(features), flat(features, directions))


def test_negative_frequencies_are_refused() -> None:
    with pytest.raises(ValueError, match=">= 0"):
        TensoRFDecoder(27, 128, True, -1, 2)


AABB = torch.tensor([[-1.0, -1.0, -1.0], [1.0, 1.0, 1.0]])


def _field(ops: GridOps) -> FourierTensoRFField:
    config = FieldConfig(
        density_components=(4, 3, 2),
        appearance_components=(4, 3, 2),
        appearance_dim=6,
        hidden_dim=16,
        decoder="tensorf",
    )
    torch.manual_seed(0)  # the decoder's layers draw from the global generator
    return FourierTensoRFField(config, AABB, [6, 7, 8], True, torch.Generator().manual_seed(0), ops=ops)


@pytest.mark.parametrize("ops", ["reference", "accelerated"])
def test_the_field_colours_through_the_tensorf_decoder_alike_in_training_and_in_renders(ops: str) -> None:
    """Training reads the factors and applies basis and decoder itself (the accelerated training path fuses only the
    few-shot decoder); renders go through the grid operations (dense tables there); the colours agree, and every
    parameter of the colour path gets a gradient."""
    accelerated = AcceleratedOps(AccelConfig(decoder_precision="float32"), "cpu")
    field = _field(GridOps() if ops == "reference" else accelerated)
    assert isinstance(field.decoder, TensoRFDecoder) and field.decoder.mlp[0].in_features == 6 * 5 + 3 * 5
    g = torch.Generator().manual_seed(3)
    xyz = torch.rand(200, 3, generator=g) * 1.8 - 0.9
    directions = torch.nn.functional.normalize(torch.randn(200, 3, generator=g), dim=-1)
    field.prepare(1.0, 1.0)
    trained = field.rgb(xyz, directions)
    trained.sum().backward()
    colour_params = [*field.appearance_grid.parameters(), *field.basis.parameters(), *field.decoder.parameters()]
    assert all(p.grad is not None and p.grad.abs().sum() > 0 for p in colour_params)
    with torch.no_grad():
        field.prepare(1.0, 1.0)
        rendered = field.rgb(xyz, directions)
    assert torch.allclose(trained.detach(), rendered, atol=1e-5)
    features = torch.cat(GridOps().features(field.appearance_grid, field.filtered.appearance, field.normalize(xyz)), -1)
    with torch.no_grad():
        assert torch.allclose(rendered, field.decoder(field.basis(features), directions), atol=1e-5)
