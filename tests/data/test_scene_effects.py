"""What a scene calls for (``data/scene_effects.py``) and what each parser declares.

The effects are decided once: a parser's declaration combined with the user's overrides (``EffectsConfig.resolve``,
None = as declared). A config whose effects are not all set must refuse to hand out effects (``effects()`` raises),
so nothing is ever built on a half-decided scene; ``EffectsConfig.of`` records resolved effects in a config. Renders
are shown on the eval background (random → white, none → black).
"""

from __future__ import annotations

import dataclasses
from pathlib import Path

import pytest

from fourierf_plugin.data.parsers.blender import BLENDER_DECLARATION, BlenderDataParserConfig
from fourierf_plugin.data.parsers.llff import LLFF_DECLARATION, LLFFDataParserConfig
from fourierf_plugin.data.scene_effects import EffectsConfig, SceneDeclaration, SceneEffects

EFFECT_NAMES = ["background", "ray_space", "view_dependent", "occlusion_regularization"]


def test_the_effects_config_covers_exactly_the_scene_effects() -> None:
    assert [f.name for f in dataclasses.fields(EffectsConfig)] == EFFECT_NAMES
    assert [f.name for f in dataclasses.fields(SceneEffects)] == EFFECT_NAMES
    assert [f.name for f in dataclasses.fields(SceneDeclaration)] == [*EFFECT_NAMES, "bounded", "reason"]


@pytest.mark.parametrize("declared", [BLENDER_DECLARATION, LLFF_DECLARATION], ids=["blender", "llff"])
def test_resolving_no_overrides_keeps_the_declared_effects(declared: SceneDeclaration) -> None:
    resolved = EffectsConfig().resolve(declared)
    assert type(resolved) is SceneEffects, "boundedness is the scene's, not an effect"
    assert dataclasses.asdict(resolved) == {name: getattr(declared, name) for name in EFFECT_NAMES}


def test_every_override_wins_and_the_others_stay_declared() -> None:
    every = EffectsConfig("random", "euclidean", view_dependent=True, occlusion_regularization=False)
    assert every.resolve(LLFF_DECLARATION) == SceneEffects("random", "euclidean", True, False)
    only_background = EffectsConfig(background="white").resolve(LLFF_DECLARATION)
    assert only_background == SceneEffects(
        background="white", ray_space="ndc", view_dependent=False, occlusion_regularization=True
    )
    # False is a value, not "unset": it must override a declared True.
    assert EffectsConfig(occlusion_regularization=False).resolve(LLFF_DECLARATION).occlusion_regularization is False


def test_is_resolved_only_when_every_effect_is_set() -> None:
    assert not EffectsConfig().is_resolved
    full = dict(background="black", ray_space="ndc", view_dependent=False, occlusion_regularization=False)
    assert EffectsConfig(**full).is_resolved
    for name in EFFECT_NAMES:
        assert not EffectsConfig(**(full | {name: None})).is_resolved, name


def test_effects_of_an_unresolved_config_raise_and_name_what_is_missing() -> None:
    with pytest.raises(ValueError, match="finalize") as info:
        EffectsConfig(background="white", view_dependent=True).effects()
    assert "ray_space" in str(info.value) and "occlusion_regularization" in str(info.value)
    assert "'background'" not in str(info.value)
    full = EffectsConfig(background="black", ray_space="ndc", view_dependent=True, occlusion_regularization=False)
    assert full.effects() == SceneEffects("black", "ndc", True, False)


@pytest.mark.parametrize(
    "effects",
    [SceneEffects(), SceneEffects("none", "ndc", True, True), SceneEffects("random", "euclidean", False, True)],
)
def test_of_records_resolved_effects_that_read_back_unchanged(effects: SceneEffects) -> None:
    config = EffectsConfig.of(effects)
    assert config.is_resolved and config.effects() == effects
    assert config.resolve(LLFF_DECLARATION) == effects, "recorded effects no longer depend on the declaration"


def test_of_a_declaration_records_its_effects_only() -> None:
    config = EffectsConfig.of(LLFF_DECLARATION)
    assert config == EffectsConfig("none", "ndc", view_dependent=False, occlusion_regularization=True)


@pytest.mark.parametrize(
    ("background", "shown_on"), [("white", "white"), ("black", "black"), ("random", "white"), ("none", "black")]
)
def test_eval_background(background: str, shown_on: str) -> None:
    assert SceneEffects(background=background).eval_background == shown_on  # type: ignore[arg-type]


def test_effects_are_frozen_and_describe_themselves() -> None:
    with pytest.raises(dataclasses.FrozenInstanceError):
        BLENDER_DECLARATION.background = "black"  # type: ignore[misc]
    effects = "background=none, rays=ndc, view-dependent=no, occlusion-regularisation=yes"
    assert LLFF_DECLARATION.describe() == f"{effects}, forward-facing"
    assert BLENDER_DECLARATION.describe().endswith(", bounded")
    default = SceneEffects().describe()
    assert default == "background=white, rays=euclidean, view-dependent=no, occlusion-regularisation=no"


# -- what the parsers declare -----------------------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("parser", "constant", "declared"),
    [
        # rendered RGBA objects: a white background, metric rays through a bounded box
        (BlenderDataParserConfig, BLENDER_DECLARATION, SceneDeclaration("white", "euclidean", False, False, True)),
        # forward-facing photos: no background, NDC rays, FreeNeRF's occlusion term
        (LLFFDataParserConfig, LLFF_DECLARATION, SceneDeclaration("none", "ndc", False, True, bounded=False)),
    ],
    ids=["blender", "llff"],
)
def test_parsers_declare_their_scene_without_reading_it(
    parser, constant: SceneDeclaration, declared: SceneDeclaration, tmp_path: Path
) -> None:
    """The declaration is what ``finalize`` resolves presets and effects from, before any file is read: it must not
    need the scene (here a folder that does not exist)."""
    assert constant == declared
    assert parser(data=tmp_path / "absent").setup().declaration() == declared
