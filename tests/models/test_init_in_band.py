"""``fourier.init_in_band``: the raw factors start low-passed at f0, so the band's filter leaves them unchanged and
nothing outside the band waits to appear as it opens; without it the initial noise is there (the paper's start)."""

from __future__ import annotations

import math

import torch

from fourierf_plugin.fields.fourier_tensorf_field import FieldConfig
from fourierf_plugin.models.fourierf import FourierConfig, FourieRFModelConfig
from tests.helpers import ndc_model


def _model(**fourier: object):
    field = FieldConfig(n_voxels_init=16**3, n_voxels_final=20**3)
    return ndc_model(FourieRFModelConfig(field=field, fourier=FourierConfig(f0_density=0.2, f0_color=0.4, **fourier)))


def _outside_band(model) -> float:
    """Largest magnitude any raw factor has outside its f0 band: plane spectra outside the disc (whose filter is a
    projection) and line spectra above the fractional edge bin."""
    field, (f_density, f_color) = model.field, model.cutoffs(0)
    with torch.no_grad():
        g = field.filter(f_density, f_color)
    worst = 0.0
    for grid, factors, f in (
        (field.density_grid, g.density, f_density),
        (field.appearance_grid, g.appearance, f_color),
    ):
        for raw, low in zip(grid.planes, factors.planes, strict=True):
            worst = max(worst, float((raw.detach() - low).abs().max()))
        for raw in grid.lines:
            spectrum = torch.fft.rfft(raw.detach(), dim=-1)
            edge = math.floor((raw.shape[-1] // 2 + 1) * f)
            worst = max(worst, float(spectrum[..., edge + 1 :].abs().max()))
    return worst


def test_raw_factors_start_inside_the_band() -> None:
    assert _outside_band(_model()) > 1e-2, "the paper's start: noise outside the band"
    inside = _model(init_in_band=True)
    assert _outside_band(inside) < 1e-5
    for p in inside.field.param_groups()["grids"]:
        assert p.requires_grad and torch.isfinite(p).all() and p.abs().max() > 0  # DC and the low band survive


def test_only_the_curriculum_filters_the_start() -> None:
    off = _model(init_in_band=True, enabled=False)  # TensoRF: nothing is band-limited, the noise is its start
    plain = _model(enabled=False)
    for a, b in zip(off.field.param_groups()["grids"], plain.field.param_groups()["grids"], strict=True):
        assert torch.equal(a, b)
