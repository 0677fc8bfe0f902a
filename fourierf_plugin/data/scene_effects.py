"""What a scene calls for (background, ray space, view dependence, occlusion regularisation), decided once.

A parser declares the effects from what it knows about its data (RGBA synthetic renders want a white background,
forward-facing photos want NDC rays and occlusion regularisation); the user may override each one
(``--pipeline.effects.*``). ``EffectsConfig.resolve`` combines the two once, before anything is built, and the
resulting ``SceneEffects`` is handed to both the datamanager (ray space) and the model (everything else).
``config.json`` records the resolved values, so a saved run never depends on the parser's defaults again.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import Literal

# "none": photos with no background; every ray must be absorbed (trained on black or white at random, shown on black).
Background = Literal["white", "black", "random", "none"]
RaySpace = Literal["euclidean", "ndc", "contracted"]
"""euclidean: rays through a bounded box; ndc: forward-facing rays in normalised device coordinates; contracted: an
unbounded scene, the inner cube [-1, 1]³ kept and the space beyond it squeezed into [-2, 2]³ (mip-NeRF 360)."""


def _yes(flag: bool) -> str:
    return "yes" if flag else "no"


@dataclass(frozen=True)
class SceneEffects:
    """The effects a model simulates; it builds only these pieces."""

    background: Background = "white"
    ray_space: RaySpace = "euclidean"
    view_dependent: bool = False
    occlusion_regularization: bool = False

    @property
    def eval_background(self) -> Background:
        """The background renders are shown and scored on: random → white, none (photos) → black."""
        return {"random": "white", "none": "black"}.get(self.background, self.background)  # type: ignore[return-value]

    def describe(self) -> str:
        return (
            f"background={self.background}, rays={self.ray_space}, view-dependent={_yes(self.view_dependent)}, "
            f"occlusion-regularisation={_yes(self.occlusion_regularization)}"
        )


@dataclass(frozen=True)
class SceneDeclaration(SceneEffects):
    """A parser's declaration: the effects its scene calls for, whether the scene is bounded (an object in a box) or
    forward-facing (which picks the real-scene preset), and why, for parsers that decide it from the data."""

    bounded: bool = True
    reason: str = ""
    """Why the parser declared this (e.g. how it told a forward-facing capture from an object); empty when fixed."""

    @property
    def kind(self) -> str:
        """object (a bounded box), unbounded (an object with its surroundings, contracted) or forward-facing."""
        if self.ray_space == "contracted":
            return "unbounded"
        return "object" if self.bounded else "forward-facing"

    @property
    def kind_label(self) -> str:
        return {"object": "object (bounded)", "unbounded": "unbounded (contracted)"}.get(self.kind, self.kind)

    def describe(self) -> str:
        return f"{super().describe()}, {'bounded' if self.kind == 'object' else self.kind}"


@dataclass
class EffectsConfig:
    """The scene's effects as the user wants them; None = as the scene declares."""

    background: Background | None = None
    """Background (Blender scenes declare white, LLFF none = photos: trained on black or white at random)."""
    ray_space: RaySpace | None = None
    """Ray space (LLFF scenes declare NDC, photo captures around an object without alpha declare contracted)."""
    view_dependent: bool | None = None
    """Whether colour depends on the view direction (few-shot scenes declare no)."""
    occlusion_regularization: bool | None = None
    """FreeNeRF's occlusion regulariser (forward-facing scenes declare it)."""

    def resolve(self, declared: SceneEffects) -> SceneEffects:
        """The declaration with every value set here taking its place."""
        names = [f.name for f in dataclasses.fields(SceneEffects)]
        values = {name: getattr(self, name) for name in names}
        return SceneEffects(**{k: getattr(declared, k) if v is None else v for k, v in values.items()})

    @property
    def is_resolved(self) -> bool:
        return all(getattr(self, f.name) is not None for f in dataclasses.fields(self))

    def effects(self) -> SceneEffects:
        """The effects this config fixes; every value must be set (``resolve`` first)."""
        if not self.is_resolved:
            missing = [f.name for f in dataclasses.fields(self) if getattr(self, f.name) is None]
            raise ValueError(
                f"the scene effects {missing} are not resolved: build the config with "
                "fourierf_plugin.method_configs.finalize (fourierf-train does), or set them explicitly"
            )
        return self.resolve(SceneEffects())

    @classmethod
    def of(cls, effects: SceneEffects) -> EffectsConfig:
        """A config that fixes exactly these effects (what ``config.json`` records)."""
        return cls(**{f.name: getattr(effects, f.name) for f in dataclasses.fields(cls)})
