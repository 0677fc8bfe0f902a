"""The regularisers a model config turns on, in the order their terms are taken, and the options they read."""

from __future__ import annotations

import dataclasses

from fourierf_plugin.data.scene_effects import SceneEffects
from fourierf_plugin.model_components import regularisers
from fourierf_plugin.model_components.regularisers import (
    DepthSmoothness,
    Distortion,
    Entropy,
    FloatersNoMore,
    Occlusion,
)
from fourierf_plugin.models.fourierf import FourieRFModelConfig
from tests.model_components.regularisers.settings import DEFAULTS, options


def test_the_options_here_are_the_model_configs_defaults() -> None:
    config = FourieRFModelConfig()
    assert {name: getattr(config, name) for name in DEFAULTS} == DEFAULTS


def test_the_defaults_turn_on_only_the_occlusion_term_and_only_where_the_scene_asks() -> None:
    assert regularisers.build(options(), SceneEffects(), 100) == []
    assert [type(r) for r in regularisers.build(options(), SceneEffects(occlusion_regularization=True), 100)] == [
        Occlusion
    ]


def test_every_one_on_comes_in_table_order_with_the_unseen_terms_depth_smoothness_first() -> None:
    everything = options(
        floaters_gradient_scaling=True, distortion_weight=0.01, depth_smoothness_weight=0.1, entropy_weight=0.001
    )
    built = regularisers.build(everything, SceneEffects(occlusion_regularization=True), 100)
    assert [type(r) for r in built] == [FloatersNoMore, Occlusion, Distortion, DepthSmoothness, Entropy]
    assert [r.unseen_name for r in built if r.unseen is not None] == ["depth_smoothness", "entropy_unseen"]
    assert len({r.name for r in built}) == len(built), "each term has a key of its own"


def test_the_model_config_counts_the_unseen_rays_of_those_it_turns_on() -> None:
    assert FourieRFModelConfig().unseen_rays() == 0
    both = dataclasses.replace(FourieRFModelConfig(), depth_smoothness_weight=0.1, entropy_weight=0.001)
    assert both.unseen_rays() == 4 * 8 * 8 + 1024
