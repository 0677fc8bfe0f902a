"""The narrow waist between dataset formats and the model: images, cameras, a box; and what the scene declares."""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Literal

from torch import Tensor

from fourierf_plugin.cameras.cameras import Cameras
from fourierf_plugin.configs.base import InstantiateConfig
from fourierf_plugin.data.dataparser_transforms import DataparserTransform
from fourierf_plugin.data.scene_effects import SceneDeclaration

Split = Literal["train", "val", "test"]


@dataclass
class DataparserOutputs:
    """One split of a scene, already resized.

    ``images`` is [N, H, W, 4] float32 in [0, 1]: colour *premultiplied* by alpha, then alpha (1 for opaque
    photos). The model composites ``rgb + (1 - alpha) * background``, so resizing and backgrounds stay exact.
    """

    images: Tensor
    cameras: Cameras
    image_names: list[str]  # the view identifiers as the dataset names them (e.g. "r_27"), for views.json
    view_ids: list[int]  # indices into the full split, in the same order as ``images``
    scene_box: Tensor  # [2, 3] axis-aligned bounding box (min, max)
    near: float
    far: float
    scene_name: str
    source_files: list[Path] = field(default_factory=list)
    depth_bounds: tuple[float, float] | None = None  # metric (near, far) of the content, e.g. for spiral paths in NDC
    dataparser_transform: DataparserTransform | None = None
    """The map from the capture's world frame to the poses above (None: not known, meshes stay normalised)."""
    object_box: tuple[tuple[float, ...], tuple[float, ...]] | None = None
    """An unbounded scene's object, in the poses' frame (None: not known); meshes are cut to it by default."""


@dataclass
class DataParserConfig(InstantiateConfig):
    """Base for dataset-format configs. ``data`` is filled from the trainer's ``--data``."""

    data: Path = Path(".")


class DataParser:
    """Reads one dataset format; ``get_outputs(split)`` returns a :class:`DataparserOutputs`."""

    config: DataParserConfig

    def __init__(self, config: DataParserConfig) -> None:
        self.config = config

    def get_outputs(self, split: Split) -> DataparserOutputs:  # pragma: no cover - interface
        raise NotImplementedError

    def declaration(self) -> SceneDeclaration:
        """What the scene calls for, known without loading images (effects and presets are resolved from it before
        anything is built)."""
        return SceneDeclaration()
