"""A scene: its primitives and light, saved as the ``geometry.json`` that ``fourierf-synth`` writes beside a dataset."""

from __future__ import annotations

import json
from dataclasses import dataclass, fields
from pathlib import Path
from typing import Any

import numpy as np

from fourierf_plugin.synthetic.primitives import Box, GroundPlane, Panel, Primitive, Sphere, Vec3, _vec3
from fourierf_plugin.synthetic.textures import Texture
from fourierf_plugin.utils.errors import fail

SCENE_FORMAT = "fourierf-synthetic-scene"
SCENE_VERSION = 1
_TYPES: dict[str, type] = {"sphere": Sphere, "box": Box, "ground_plane": GroundPlane, "panel": Panel}
_TYPE_NAMES = {cls: name for name, cls in _TYPES.items()}


@dataclass(frozen=True)
class SceneSpec:
    """The primitives of a scene and the light used only by ``shading="lambert"``."""

    primitives: tuple[Primitive, ...]
    light_direction: Vec3 = (0.3, 0.2, 1.0)
    """Direction towards the light (normalised when used)."""
    ambient: float = 0.25
    """Lambert: colour = albedo * (ambient + (1 - ambient) * max(0, n . l))."""

    def __post_init__(self) -> None:
        prims = tuple(self.primitives)
        if not prims:
            raise ValueError("a scene needs at least one primitive")
        for p in prims:
            if not isinstance(p, (Sphere, Box, GroundPlane, Panel)):
                raise ValueError(f"unknown primitive {p!r}")
        light = _vec3(self.light_direction, "light_direction")
        if np.linalg.norm(light) == 0:
            raise ValueError("light_direction must be non-zero")
        if not 0.0 <= float(self.ambient) <= 1.0:
            raise ValueError(f"ambient must lie in [0, 1], got {self.ambient!r}")
        object.__setattr__(self, "primitives", prims)
        object.__setattr__(self, "light_direction", light)
        object.__setattr__(self, "ambient", float(self.ambient))

    def bounds(self) -> tuple[np.ndarray, np.ndarray]:
        """Axis-aligned box holding every primitive."""
        boxes = [p.bounds() for p in self.primitives]
        return np.min([b[0] for b in boxes], axis=0), np.max([b[1] for b in boxes], axis=0)

    def to_dict(self) -> dict[str, Any]:
        prims = []
        for p in self.primitives:
            item: dict[str, Any] = {"type": _TYPE_NAMES[type(p)]}
            for f in fields(p):
                value = getattr(p, f.name)
                if isinstance(value, Texture):
                    item[f.name] = value.to_dict()
                elif f.name != "texture":  # no texture: no key, so a flat-coloured primitive's JSON stays minimal
                    item[f.name] = list(value) if isinstance(value, tuple) else value
            prims.append(item)
        return {
            "format": SCENE_FORMAT,
            "version": SCENE_VERSION,
            "primitives": prims,
            "light_direction": list(self.light_direction),
            "ambient": self.ambient,
        }

    @classmethod
    def from_dict(cls, data: Any, source: str = "scene") -> SceneSpec:
        """Inverse of :meth:`to_dict`; every defect is a UserError naming ``source`` and the primitive."""
        fix = "repair the file (see geometry.json written by fourierf-synth for the format)"
        if not isinstance(data, dict) or not isinstance(data.get("primitives"), list):
            fail(f"{source} must be a JSON object with a 'primitives' list", fix)
        if data.get("format", SCENE_FORMAT) != SCENE_FORMAT:
            fail(f"{source} has format {data.get('format')!r}, expected {SCENE_FORMAT!r}", fix)
        prims: list[Primitive] = []
        for i, item in enumerate(data["primitives"]):
            kind = item.get("type") if isinstance(item, dict) else None
            if kind not in _TYPES:
                fail(f"{source}, primitive {i}: type must be one of {sorted(_TYPES)}, got {kind!r}", fix)
            kwargs = {k: v for k, v in item.items() if k != "type"}
            try:
                prims.append(_TYPES[kind](**kwargs))
            except (TypeError, ValueError) as err:
                fail(f"{source}, primitive {i} ({kind}): {err}", fix)
        extra = {k: data[k] for k in ("light_direction", "ambient") if k in data}
        try:
            return cls(tuple(prims), **extra)
        except (TypeError, ValueError) as err:
            fail(f"{source}: {err}", fix)


def save_scene(spec: SceneSpec, path: Path, extra: dict[str, Any] | None = None) -> Path:
    """Write ``spec`` as JSON (``extra`` keys, e.g. how it was rendered, are stored beside it and ignored on load)."""
    path = Path(path)
    data = spec.to_dict()
    if extra:
        data.update(extra)
    path.write_text(json.dumps(data, indent=2) + "\n", encoding="utf-8")
    return path


def load_scene(path: Path) -> SceneSpec:
    path = Path(path)
    if not path.is_file():
        fail(f"scene file not found: {path}", "pass the geometry.json of a generated scene")
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
    except json.JSONDecodeError as err:
        fail(f"{path} is not valid JSON: {err.msg} at line {err.lineno}", "repair the file")
    except (UnicodeDecodeError, OSError) as err:
        fail(f"cannot read {path}: {err}", "check the file")
    return SceneSpec.from_dict(data, str(path))


def default_scene(ground_plane: bool = False) -> SceneSpec:
    """Two spheres and a box of distinct colours inside [-1, 1]^3; the box cuts into the large sphere.

    Colours are multiples of 0.2, exact in 8 bits, so unshaded renders hold exactly these values.
    """
    prims: list[Primitive] = [
        Sphere(center=(-0.3, -0.15, 0.0), radius=0.5, color=(0.8, 0.2, 0.2)),
        Sphere(center=(0.5, 0.45, -0.2), radius=0.3, color=(0.2, 0.8, 0.2)),
        Box(center=(0.35, -0.45, -0.25), half_size=(0.3, 0.25, 0.4), color=(0.2, 0.4, 0.8)),
    ]
    if ground_plane:
        prims.append(GroundPlane(height=-0.6, color=(0.6, 0.6, 0.6), half_extent=1.0))
    return SceneSpec(tuple(prims))
