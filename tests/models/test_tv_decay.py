"""TensoRF's TV-weight decay: both TV terms of ``loss_dict`` scaled by ``tv_decay_ratio ** (step / max_iters)``."""

from __future__ import annotations

import math

import pytest
import torch

from fourierf_plugin.fields.fourier_tensorf_field import FieldConfig
from fourierf_plugin.models.fourierf import FourieRFModelConfig
from tests.helpers import ndc_model

MAX_ITERS = 100


def _tv_terms(ratio: float | None, steps: tuple[int, ...]) -> list[dict[str, float]]:
    """The loss terms of one forward on a fresh 16³ model, taken at each of ``steps`` (same grids, same output)."""
    field = FieldConfig(n_voxels_init=4096, n_voxels_final=13824)
    model = ndc_model(FourieRFModelConfig(field=field, tv_decay_ratio=ratio), max_iters=MAX_ITERS)
    model.prepare(0)
    g = torch.Generator().manual_seed(1)
    origins = torch.cat([(torch.rand(8, 2, generator=g) - 0.5) * 2, -torch.ones(8, 1)], dim=-1)
    out = model.train()(origins, torch.tensor([[0.0, 0.0, 2.0]]).expand(8, 3))
    target = torch.full((8, 4), 0.5)
    return [{k: float(v.detach()) for k, v in model.loss_dict(out, target, s).items()} for s in steps]


def test_both_tv_terms_decay_with_the_step_and_nothing_else_does() -> None:
    start, half, end = _tv_terms(0.1, (0, MAX_ITERS // 2, MAX_ITERS))
    assert start["tv_density"] > 0 and start["tv_appearance"] > 0
    for key in ("tv_density", "tv_appearance"):
        assert half[key] == pytest.approx(math.sqrt(0.1) * start[key], rel=1e-6), key
        assert end[key] == pytest.approx(0.1 * start[key], rel=1e-6), key
    for key in ("mse", "occlusion"):
        assert start[key] == half[key] == end[key], f"{key} must not decay"


@pytest.mark.parametrize("ratio", [None, 1.0])
def test_no_decay_when_unset_or_one(ratio: float | None) -> None:
    start, end = _tv_terms(ratio, (0, MAX_ITERS))
    assert start["tv_density"] == end["tv_density"] and start["tv_appearance"] == end["tv_appearance"]
