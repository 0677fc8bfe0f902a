"""The TensoRF baseline is FourieRF with the curriculum removed, and nothing else: with its band open from step 0,
fourierf-vm trains bit for bit like tensorf-vm, so every gap the benchmarks report is the curriculum's."""

from __future__ import annotations

import pytest
import torch

from tests.helpers import train_tiny

pytestmark = pytest.mark.slow
ITERS = 20
OPEN_BAND = ["--pipeline.model.fourier.f0-density", "1", "--pipeline.model.fourier.f0-color", "1"]


@pytest.mark.parametrize(
    "extra",
    [[], ["--pipeline.model.floaters-gradient-scaling", "True"]],
    ids=["rule", "floaters-no-more"],
)
def test_fourierf_with_an_open_band_trains_exactly_like_tensorf(tmp_path, extra: list[str]) -> None:
    fourierf, _ = train_tiny(tmp_path / "fourierf", "fourierf-vm", ITERS, [*OPEN_BAND, *extra])
    tensorf, _ = train_tiny(tmp_path / "tensorf", "tensorf-vm", ITERS, extra)
    ours, theirs = fourierf.pipeline.model.state_dict(), tensorf.pipeline.model.state_dict()
    assert ours.keys() == theirs.keys()
    for name, value in ours.items():
        assert torch.equal(value, theirs[name]), f"{name} differs after {ITERS} steps"
    assert fourierf.pipeline.model.cutoffs(0) == (1.0, 1.0), "the band was open from the first step"
