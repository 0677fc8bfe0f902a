"""TensoRF's colour decoder (its ``MLP_Fea`` shading mode): the appearance feature and the view direction, each beside
its sinusoidal encoding, through three linear layers with ReLU between them and a sigmoid.

TensoRF's published Blender model encodes both with 2 frequencies (150 inputs for a 27-wide feature); its LLFF model
feeds both without encoding (0 frequencies, 30 inputs). Without view dependence the direction is left out entirely.
"""

from __future__ import annotations

import torch
from torch import Tensor, nn


def frequency_encoding(x: Tensor, frequencies: int) -> Tensor:
    """``[..., D] -> [..., 2·D·F]``: ``sin(2^k x_d)`` for each channel ``d`` and ``k < F``, the ``F`` bands of a
    channel together, then every cosine in the same order (no π factor; TensoRF's ``positional_encoding``)."""
    if frequencies < 0:
        raise ValueError(f"the number of encoding frequencies must be >= 0, got {frequencies}")
    bands = 2.0 ** torch.arange(frequencies, dtype=x.dtype, device=x.device)
    scaled = (x.unsqueeze(-1) * bands).flatten(-2)
    return torch.cat([torch.sin(scaled), torch.cos(scaled)], dim=-1)


class TensoRFDecoder(nn.Module):
    """``rgb = sigmoid(W₃ relu(W₂ relu(W₁ [a, d, enc(a), enc(d)])))``, the output layer's bias starting at 0."""

    def __init__(
        self,
        in_dim: int,
        hidden_dim: int = 128,
        view_dependent: bool = True,
        feature_frequencies: int = 2,
        view_frequencies: int = 2,
    ) -> None:
        super().__init__()
        if feature_frequencies < 0 or view_frequencies < 0:
            raise ValueError(
                f"encoding frequencies must be >= 0, got {feature_frequencies} (feature), {view_frequencies} (view)"
            )
        self.feature_frequencies = feature_frequencies
        self.view_frequencies = view_frequencies
        self._view_dependent = view_dependent
        width = in_dim * (1 + 2 * feature_frequencies) + (3 * (1 + 2 * view_frequencies) if view_dependent else 0)
        self.mlp = nn.Sequential(
            nn.Linear(width, hidden_dim),
            nn.ReLU(),
            nn.Linear(hidden_dim, hidden_dim),
            nn.ReLU(),
            nn.Linear(hidden_dim, 3),
        )
        nn.init.zeros_(self.mlp[-1].bias)

    @property
    def view_dependent(self) -> bool:
        return self._view_dependent

    def forward(self, features: Tensor, directions: Tensor | None = None) -> Tensor:
        """Colour in [0, 1] [N, 3] from features [N, in_dim] and, when view-dependent, unit directions [N, 3]."""
        inputs = [features]
        if self._view_dependent:
            if directions is None:
                raise ValueError("a view-dependent decoder needs ray directions")
            inputs.append(directions)
        if self.feature_frequencies:
            inputs.append(frequency_encoding(features, self.feature_frequencies))
        if self._view_dependent and self.view_frequencies:
            inputs.append(frequency_encoding(directions, self.view_frequencies))  # type: ignore[arg-type]
        return torch.sigmoid(self.mlp(torch.cat(inputs, dim=-1)))
