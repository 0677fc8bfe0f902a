"""The appearance basis and decoder as one autograd function that works through the points in cache-sized chunks.

Why: in training the colour MLP runs on ~50k shaded samples per iteration. Through autograd every layer writes and
later re-reads a [N, 128] activation from main memory (four of them per iteration, ~25 MB each), and the per-group
features are first concatenated. Here the forward keeps only the basis output [N, D] and the colours; the backward
recomputes each chunk's hidden layer while it is still in cache and writes the feature gradients in place. Same
arithmetic as ``basis`` then ``AppearanceDecoder`` (float32, equal to rounding); no extra memory.
"""

from __future__ import annotations

from collections.abc import Sequence

import torch
import torch.nn.functional as F
from torch import Tensor

from fourierf_plugin.field_components.decoder import AppearanceDecoder

CHUNK_ROWS = 8192
"""Rows per chunk: a [8192, 128] float32 activation is 4 MB, inside this CPU's L2 + L3 share per core."""
PAD_TO = 16
"""The basis output (27 wide in TensoRF) is padded with zero rows of the basis to a multiple of this: MKL's products
with 27 columns run ~1.5x slower than with 32. The padded columns are exactly 0 (and silu(0) = 0), so nothing
changes but speed; their gradients are dropped."""


class _FusedDecoder(torch.autograd.Function):
    @staticmethod
    def forward(ctx, view_term, basis_weight, w_hidden, b_hidden, w_out, b_out, *features):  # type: ignore[override]
        widths = [f.shape[1] for f in features]
        dim = basis_weight.shape[0]
        basis_weight, w_hidden = F.pad(basis_weight, (0, 0, 0, -dim % PAD_TO)), F.pad(w_hidden, (0, -dim % PAD_TO))
        basis_parts = basis_weight.split(widths, dim=1)
        n = features[0].shape[0]
        projected = features[0].new_empty(n, basis_weight.shape[0])
        rgb = features[0].new_empty(n, w_out.shape[0])
        for lo in range(0, n, CHUNK_ROWS):
            hi = min(lo + CHUNK_ROWS, n)
            a = projected[lo:hi]
            torch.mm(features[0][lo:hi], basis_parts[0].T, out=a)
            for f, part in zip(features[1:], basis_parts[1:], strict=True):
                a.addmm_(f[lo:hi], part.T)
            h = torch.addmm(b_hidden, F.silu(a), w_hidden.T)
            if view_term is not None:
                h += view_term[lo:hi]
            torch.sigmoid(torch.addmm(b_out, F.silu(h), w_out.T), out=rgb[lo:hi])
        ctx.save_for_backward(view_term, basis_weight, w_hidden, b_hidden, w_out, projected, rgb, *features)
        ctx.widths, ctx.dim = widths, dim
        return rgb

    @staticmethod
    def backward(ctx, grad_rgb):  # type: ignore[override]
        view_term, basis_weight, w_hidden, b_hidden, w_out, projected, rgb, *features = ctx.saved_tensors
        basis_parts = basis_weight.split(ctx.widths, dim=1)
        n = projected.shape[0]
        grad_view = torch.empty_like(view_term) if view_term is not None and ctx.needs_input_grad[0] else None
        grad_features = [torch.empty_like(f) if ctx.needs_input_grad[6 + i] else None for i, f in enumerate(features)]
        grad_basis = torch.zeros_like(basis_weight)
        grad_basis_parts = grad_basis.split(ctx.widths, dim=1)
        grad_w_hidden, grad_b_hidden = torch.zeros_like(w_hidden), torch.zeros_like(b_hidden)
        grad_w_out, grad_b_out = torch.zeros_like(w_out), grad_rgb.new_zeros(w_out.shape[0])
        for lo in range(0, n, CHUNK_ROWS):
            hi = min(lo + CHUNK_ROWS, n)
            a = projected[lo:hi]
            s = F.silu(a)
            h = torch.addmm(b_hidden, s, w_hidden.T)
            if view_term is not None:
                h += view_term[lo:hi]
            y = rgb[lo:hi]
            grad_o = grad_rgb[lo:hi] * y * (1.0 - y)
            grad_w_out.addmm_(grad_o.T, F.silu(h))
            grad_b_out += grad_o.sum(dim=0)
            grad_h = torch.ops.aten.silu_backward(grad_o @ w_out, h)
            if grad_view is not None:
                grad_view[lo:hi] = grad_h
            grad_w_hidden.addmm_(grad_h.T, s)
            grad_b_hidden += grad_h.sum(dim=0)
            grad_a = torch.ops.aten.silu_backward(grad_h @ w_hidden, a)
            for f, part, grad_part, grad_f in zip(features, basis_parts, grad_basis_parts, grad_features, strict=True):
                grad_part.addmm_(grad_a.T, f[lo:hi])
                if grad_f is not None:
                    torch.mm(grad_a, part, out=grad_f[lo:hi])
        grad_basis, grad_w_hidden = grad_basis[: ctx.dim], grad_w_hidden[:, : ctx.dim].contiguous()  # drop the padding
        return grad_view, grad_basis, grad_w_hidden, grad_b_hidden, grad_w_out, grad_b_out, *grad_features


def fused_decode(
    features: Sequence[Tensor], basis_weight: Tensor, decoder: AppearanceDecoder, directions: Tensor | None
) -> Tensor:
    """``decoder(cat(features) @ basis_weight.T, directions)`` for float32 [N, C_i] feature groups, chunked.

    The view-dependent term (if any) is computed by the decoder's own layer and added inside, so its gradient
    flows through autograd as usual.
    """
    view_term = decoder.view_term(directions)
    hidden, out = decoder.feature_layer, decoder.output_layer
    feats = [f.contiguous() for f in features]
    return _FusedDecoder.apply(view_term, basis_weight, hidden.weight, hidden.bias, out.weight, out.bias, *feats)
