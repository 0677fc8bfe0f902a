"""Appearance decoder without positional encoding (the paper's few-shot decoder; ZeroRF-style).

``h = W_a SiLU(a) [+ W_d SH₂(d)]``, ``rgb = sigmoid(W_o SiLU(h))``. The view term exists only when the scene
asks for view-dependent colour; few-shot scenes default to none, since a handful of views cannot constrain it.
"""

from __future__ import annotations

import torch
import torch.nn.functional as F
from torch import Tensor, nn

_C0 = 0.28209479177387814
_C1 = 0.4886025119029199
_C2 = (1.0925484305920792, -1.0925484305920792, 0.31539156525252005, -1.0925484305920792, 0.5462742152960396)


def spherical_harmonics_deg2(d: Tensor) -> Tensor:
    """Real spherical harmonics up to degree 2 of unit directions [N, 3] -> [N, 9]."""
    x, y, z = d.unbind(-1)
    return torch.stack(
        [
            torch.full_like(x, _C0),
            -_C1 * y,
            _C1 * z,
            -_C1 * x,
            _C2[0] * x * y,
            _C2[1] * y * z,
            _C2[2] * (2.0 * z * z - x * x - y * y),
            _C2[3] * x * z,
            _C2[4] * (x * x - y * y),
        ],
        dim=-1,
    )


class AppearanceDecoder(nn.Module):
    def __init__(self, in_dim: int, hidden_dim: int = 128, view_dependent: bool = False) -> None:
        super().__init__()
        self.feature_layer = nn.Linear(in_dim, hidden_dim)
        self.view_layer = nn.Linear(9, hidden_dim) if view_dependent else None
        self.output_layer = nn.Linear(hidden_dim, 3)

    @property
    def view_dependent(self) -> bool:
        return self.view_layer is not None

    def view_term(self, directions: Tensor | None) -> Tensor | None:
        """The view-dependent part of the hidden layer, ``W_d SH₂(d)`` [N, hidden] (None for a view-independent
        decoder)."""
        if self.view_layer is None:
            return None
        if directions is None:
            raise ValueError("a view-dependent decoder needs ray directions")
        return self.view_layer(spherical_harmonics_deg2(directions))

    def forward(self, features: Tensor, directions: Tensor | None = None) -> Tensor:
        h = self.feature_layer(F.silu(features))
        view = self.view_term(directions)
        if view is not None:
            h = h + view
        return torch.sigmoid(self.output_layer(F.silu(h)))
