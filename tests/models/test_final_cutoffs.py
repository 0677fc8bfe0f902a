"""The final cutoffs: the ramp ends at ``f_final`` for the density grids and at ``f_final_color`` (default: the
same) for the appearance grids, so the geometry alone can stay band-limited."""

from __future__ import annotations

import pytest

from fourierf_plugin.fields.fourier_tensorf_field import FieldConfig
from fourierf_plugin.models.fourierf import FourierConfig, FourieRFModelConfig
from tests.helpers import ndc_model

MAX_ITERS = 100


def _cutoffs(fourier: FourierConfig, steps: tuple[int, ...]) -> list[tuple[float, float]]:
    field = FieldConfig(n_voxels_init=4096, n_voxels_final=13824)
    model = ndc_model(FourieRFModelConfig(field=field, fourier=fourier), max_iters=MAX_ITERS)
    return [model.cutoffs(s) for s in steps]


def test_the_colour_cutoff_follows_the_shared_final_cutoff_unless_given_its_own() -> None:
    shared = FourierConfig(f0_density=0.3, f0_color=0.3, ramp_fraction=0.5, f_final=0.7)
    assert _cutoffs(shared, (50, 100)) == [(pytest.approx(0.7), pytest.approx(0.7))] * 2
    geometry_only = FourierConfig(f0_density=0.3, f0_color=0.3, ramp_fraction=0.5, f_final=0.7, f_final_color=1.0)
    start, half_ramp, end_of_ramp, end = _cutoffs(geometry_only, (0, 25, 50, 100))
    assert start == (0.3, 0.3)
    assert half_ramp == (pytest.approx(0.5), pytest.approx(0.65))  # each ramp runs to its own end, over the same steps
    assert end_of_ramp == end == (pytest.approx(0.7), 1.0)


def test_the_tensorf_baseline_ignores_both() -> None:
    off = FourierConfig(enabled=False, f_final=0.5, f_final_color=0.5)
    assert _cutoffs(off, (0, 100)) == [(1.0, 1.0)] * 2
