"""The fused basis + decoder (``accel.fused_decoder``) equals the reference ``decoder(basis(cat(features)))`` in values
and all gradients, including a partial last chunk and no rows at all."""

from __future__ import annotations

import pytest
import torch
from torch import nn

from fourierf_plugin.accel import fused_decoder
from fourierf_plugin.accel.fused_decoder import fused_decode
from fourierf_plugin.field_components.decoder import AppearanceDecoder

Setup = tuple[list[torch.Tensor], nn.Linear, AppearanceDecoder, torch.Tensor | None]


def _setup(n: int, view_dependent: bool) -> Setup:
    torch.manual_seed(0)
    basis = nn.Linear(9, 5, bias=False).double()
    decoder = AppearanceDecoder(5, 16, view_dependent).double()
    g = torch.Generator().manual_seed(1)
    features = [torch.randn(n, c, generator=g, dtype=torch.float64, requires_grad=True) for c in (2, 3, 4)]
    directions = None
    if view_dependent:
        directions = nn.functional.normalize(torch.randn(n, 3, generator=g, dtype=torch.float64), dim=-1)
        directions.requires_grad_()
    return features, basis, decoder, directions


@pytest.mark.parametrize("view_dependent", [False, True])
@pytest.mark.parametrize("n", [0, 1, 7, 23])  # 23 rows with 7-row chunks: a partial last chunk
def test_fused_decode_equals_the_module_path(monkeypatch: pytest.MonkeyPatch, n: int, view_dependent: bool) -> None:
    monkeypatch.setattr(fused_decoder, "CHUNK_ROWS", 7)
    features, basis, decoder, directions = _setup(n, view_dependent)
    inputs = [*features, basis.weight, *decoder.parameters()] + ([directions] if directions is not None else [])
    expected = decoder(basis(torch.cat(features, dim=-1)), directions)
    got = fused_decode(features, basis.weight, decoder, directions)
    torch.testing.assert_close(got, expected, atol=1e-13, rtol=0)
    upstream = torch.rand(n, 3, generator=torch.Generator().manual_seed(2), dtype=torch.float64)
    grads_expected = torch.autograd.grad(expected, inputs, upstream, allow_unused=True)
    grads_got = torch.autograd.grad(got, inputs, upstream, allow_unused=True)
    for a, b in zip(grads_got, grads_expected, strict=True):
        torch.testing.assert_close(a, b, atol=1e-12, rtol=0)


def test_fused_decode_passes_gradcheck() -> None:
    features, basis, decoder, directions = _setup(5, view_dependent=True)
    w = basis.weight.detach().requires_grad_()

    def run(*feats: torch.Tensor) -> torch.Tensor:
        return fused_decode(list(feats[:3]), feats[3], decoder, feats[4])

    assert torch.autograd.gradcheck(run, (*features, w, directions))
