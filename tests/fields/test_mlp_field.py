"""The MLP field: what the masked bands reach, and its size."""

from __future__ import annotations

import torch

from fourierf_plugin.fields.mlp_field import MLPField, MLPFieldConfig, parameter_count


def _field(config: MLPFieldConfig, view_dependent: bool = True) -> MLPField:
    box = torch.tensor([[-1.0] * 3, [1.0] * 3])
    return MLPField(config, box, [4, 4, 4], view_dependent, torch.Generator().manual_seed(0))


def test_the_hidden_bands_reach_no_output() -> None:
    """With no band visible the bands' inputs are zero: the first layer's weights on the raw position train, those on
    the bands get no gradient."""
    field = _field(MLPFieldConfig(depth=2, width=8, skip=0, view_width=8))
    field.prepare(0.0, 0.0)
    xyz = torch.rand(64, 3, generator=torch.Generator().manual_seed(1)) * 2 - 1
    field.density(xyz).sum().backward()
    first = field.trunk[0].weight.grad
    assert first[:, :3].abs().sum() > 0, "the raw input is trained"
    assert first[:, 3:].abs().sum() == 0, "the masked bands are not"


def test_parameter_count_matches_the_network() -> None:
    for config, view_dependent in ((MLPFieldConfig(), True), (MLPFieldConfig(skip=0, position_bands=2), False)):
        field = _field(config, view_dependent)
        assert sum(p.numel() for p in field.parameters()) == parameter_count(config, view_dependent)
