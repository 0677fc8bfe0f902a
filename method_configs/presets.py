"""The built-in method presets: FourieRF and its TensoRF baseline, VM and CP.

``fourierf-vm`` is the paper's synthetic preset (f0 = 0.3, fully open at 20% of the run, TV 1.0 on planes,
AdamW (0.9, 0.98) with weight decay 0.2, no positional encoding). The ``tensorf-*`` presets run the identical
pipeline with the Fourier masks off, so any difference is the curriculum.
"""

from __future__ import annotations

from dataclasses import replace

from fourierf_plugin.data.scene_effects import EffectsConfig
from fourierf_plugin.engine.optimizers import OptimizerConfig
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


def _code_vm_model() -> FourieRFModelConfig:
    """The official code's shipped behaviour (spec §4.7, §8): f0 0.01 ramped over the whole run, out-of-band plane
    coefficients kept at 1e-6, appearance planes filtered with the density cutoff (and, in its preset, a view-dependent
    SH decoder)."""
    return FourieRFModelConfig(
        field=FieldConfig(decomposition="vm"),
        fourier=FourierConfig(
            f0_density=0.01, f0_color=0.01, ramp_fraction=1.0, plane_leakage=1e-6, app_planes_follow_density=True
        ),
    )


def _trainer(
    name: str,
    model: FourieRFModelConfig,
    optimizer: OptimizerConfig | None = None,
    effects: EffectsConfig | None = None,
) -> TrainerConfig:
    return TrainerConfig(
        method_name=name,
        pipeline=replace(PipelineConfig(), model=model, effects=effects or EffectsConfig()),
        optimizer=optimizer or OptimizerConfig(),
    )


fourierf_vm = _trainer("fourierf-vm", _vm_model(fourier=True))
fourierf_cp = _trainer("fourierf-cp", _cp_model(fourier=True))
fourierf_vm_code = _trainer(
    "fourierf-vm-code",
    _code_vm_model(),
    OptimizerConfig(betas=(0.9, 0.99), weight_decay=0.0, lr_decay_ratio=1.0),
    EffectsConfig(view_dependent=True),
)
tensorf_vm = _trainer("tensorf-vm", _vm_model(fourier=False))
tensorf_cp = _trainer("tensorf-cp", _cp_model(fourier=False))

descriptions = {
    "fourierf-vm": "FourieRF, VM field (planes x lines), the paper's synthetic preset.",
    "fourierf-cp": "FourieRF with the CP field (lines only).",
    "fourierf-vm-code": "FourieRF as the official code ships it (f0 0.01 over the whole run, no weight decay).",
    "tensorf-vm": "Baseline: the same pipeline with the Fourier masks off (TensoRF VM).",
    "tensorf-cp": "Baseline: the same pipeline with the Fourier masks off (TensoRF CP).",
}
