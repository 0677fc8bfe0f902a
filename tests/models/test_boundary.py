"""``fourier.boundary``: periodic filters (the paper's) or mirror ones, for the free factors and ZeroRF's alike.

Why it matters: the circular filter puts what lies at one face of the box onto the opposite one while the band is
narrow (on NDC, the far wall onto the near plane); mirror boundaries do not, and the option must reach whichever
field the model builds.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path

import pytest
import torch

from fourierf_plugin.field_components import fourier
from fourierf_plugin.fields.fourier_tensorf_field import FieldConfig
from fourierf_plugin.models.fourierf import FourierConfig, FourieRFModelConfig
from fourierf_plugin.scripts import train as train_script
from tests.helpers import TINY_SCENE, cli_exit_code, ndc_model
from tests.models.test_zerorf import _model as zerorf_model


def _model(boundary: str):
    field = FieldConfig(n_voxels_init=16**3, n_voxels_final=20**3)
    return ndc_model(FourieRFModelConfig(field=field, fourier=FourierConfig(boundary=boundary)))  # type: ignore[arg-type]


def test_mirror_boundaries_filter_the_free_factors_without_wrapping() -> None:
    periodic, mirror = _model("periodic"), _model("mirror")
    assert not periodic.field.mirror_boundary and mirror.field.mirror_boundary
    raw = mirror.field.density_grid.planes[0]
    with torch.no_grad():
        mirrored = mirror.field.filter(0.3, 0.3).density.planes[0]
        wrapped = periodic.field.filter(0.3, 0.3).density.planes[0]
    torch.testing.assert_close(mirrored, fourier.mirrored(fourier.filter_planes, raw.detach(), 0.3, 2, 0.0))
    assert not torch.allclose(mirrored, wrapped)


def test_mirror_boundaries_reach_the_zerorf_field_and_keep_gradients() -> None:
    preset = zerorf_model()
    model = zerorf_model(fourier=dataclasses.replace(preset.config.fourier, boundary="mirror"))
    assert model.field.mirror_boundary and not preset.field.mirror_boundary
    model.field.prepare(0.3, 0.3)
    xyz = torch.rand(64, 3) * 2 - 1
    model.field.density(xyz).sum().backward()
    grads = [p.grad for p in model.field.parameters() if p.grad is not None]
    assert grads and all(torch.isfinite(g).all() for g in grads)


def test_an_unknown_boundary_is_refused_naming_the_flag_and_the_choices(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    flag = "--pipeline.model.fourier.boundary"
    args = ["fourierf-vm", "--data", str(TINY_SCENE), "--output-dir", str(tmp_path), flag, "wrap"]
    assert cli_exit_code(train_script.main, args) == 2
    err = " ".join(capsys.readouterr().err.split())
    assert "wrap" in err and flag in err and "mirror" in err and "periodic" in err
    assert not any(tmp_path.iterdir()), "a refused run leaves nothing behind"
