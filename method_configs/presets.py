"""The built-in method presets: FourieRF and its TensoRF baseline, VM and CP.

``fourierf-vm`` is the paper's synthetic preset (f0 = 0.3, fully open at 20% of the run, TV 1.0 on planes,
AdamW (0.9, 0.98) with weight decay 0.2, no positional encoding). The ``tensorf-*`` presets run the identical
pipeline with the Fourier masks off, so any difference is the curriculum.
"""

from __future__ import annotations

from dataclasses import replace

from fourierf_plugin.engine.trainer import TrainerConfig
from fourierf_plugin.fields.fourier_tensorf_field import FieldConfig
from fourierf_plugin.models.fourierf import FourierConfig, FourieRFModelConfig
from fourierf_plugin.pipelines.base import PipelineConfig


def _vm_model(fourier: bool) -> FourieRFModelConfig:
    return FourieRFModelConfig(field=FieldConfig(decomposition="vm"), fourier=FourierConfig(enabled=fourier))


def _cp_model(fourier: bool) -> FourieRFModelConfig:
    """TensoRF's CP setting: 96 density / 288 appearance rank-one components, 500³ final grid, light L1."""
    return FourieRFModelConfig(
        field=FieldConfig(
            decomposition="cp",
            density_components=(96, 96, 96),
            appearance_components=(288, 288, 288),
            n_voxels_final=500**3,
        ),
        fourier=FourierConfig(enabled=fourier),
        l1_weight_initial=1e-5,
        l1_weight_rest=1e-5,
    )


def _trainer(name: str, model: FourieRFModelConfig) -> TrainerConfig:
    return TrainerConfig(method_name=name, pipeline=replace(PipelineConfig(), model=model))


fourierf_vm = _trainer("fourierf-vm", _vm_model(fourier=True))
fourierf_cp = _trainer("fourierf-cp", _cp_model(fourier=True))
tensorf_vm = _trainer("tensorf-vm", _vm_model(fourier=False))
tensorf_cp = _trainer("tensorf-cp", _cp_model(fourier=False))

descriptions = {
    "fourierf-vm": "FourieRF, VM field (planes x lines), the paper's synthetic preset.",
    "fourierf-cp": "FourieRF with the CP field (lines only).",
    "tensorf-vm": "Baseline: the same pipeline with the Fourier masks off (TensoRF VM).",
    "tensorf-cp": "Baseline: the same pipeline with the Fourier masks off (TensoRF CP).",
}
