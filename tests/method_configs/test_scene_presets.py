"""The real-scene preset: what it changes for the FourieRF/TensoRF presets and what it leaves to ZeroRF."""

from __future__ import annotations

import copy

from fourierf_plugin.method_configs import all_methods
from fourierf_plugin.method_configs.scene_presets import REAL_SCENE_SETTINGS, apply_real_scene_preset


def test_zerorf_takes_only_the_pipeline_schedule_from_the_real_scene_preset() -> None:
    """ZeroRF keeps its own weight decay and no L1 on a forward-facing scene; the occupancy and upsample schedule are
    the pipeline's and change as for every method."""
    config = copy.deepcopy(all_methods["zerorf-vm"])
    applied, kept = apply_real_scene_preset(config, all_methods["zerorf-vm"])
    assert not kept
    assert sorted(name.split("=")[0] for name in applied) == ["occupancy_update_fractions", "upsample_fractions"]
    assert config.optimizer.weight_decay == all_methods["zerorf-vm"].optimizer.weight_decay == 0.2
    assert config.pipeline.model.l1_weight_initial == config.pipeline.model.l1_weight_rest == 0.0
    assert (
        config.pipeline.model.occupancy_update_fractions
        == REAL_SCENE_SETTINGS["pipeline.model.occupancy_update_fractions"]
    )


def test_fourierf_takes_the_whole_real_scene_preset() -> None:
    config = copy.deepcopy(all_methods["fourierf-vm"])
    applied, _ = apply_real_scene_preset(config, all_methods["fourierf-vm"])
    assert config.optimizer.weight_decay == 0.0 and config.pipeline.model.l1_weight_initial == 1e-4
    assert len(applied) == len(REAL_SCENE_SETTINGS) + 2  # and the VM component counts
