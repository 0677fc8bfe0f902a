"""Config dataclasses that build their component, and a data-only JSON round trip for them.

Every component has a config with a ``_target`` (the class it builds) and ``setup(**runtime_kwargs)``. Runtime
values (device, scene box, ...) are passed to ``setup`` and never stored, so a saved config is plain data.
JSON (not pickled YAML) keeps ``config.json`` readable and safe: a class named in it must be the one a field
declares or one of the registry the caller passes, so loading one cannot import or run arbitrary code. The registry
comes from the layer that knows every plugin (``fourierf_plugin.method_configs.config_registry``); this module
imports none.
"""

from __future__ import annotations

import dataclasses
import json
import types
import typing
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import Any, ClassVar, Literal, TypeVar, Union, get_args, get_origin

from fourierf_plugin import __version__
from fourierf_plugin.utils.errors import fail
from fourierf_plugin.utils.files import check_reachable, write_text_atomic

C = TypeVar("C", bound="InstantiateConfig")
CONFIG_FORMAT = 4
"""4: no ``fourier.init_in_band``, ZeroRF's silhouette term (``alpha_weight``); 3: ZeroRF's model config of its own
(``pipeline.model.zerorf``), the plain grid operations named ``reference-grid-ops``; 2: scene effects under
``pipeline.effects`` (resolved), speed settings under ``pipeline.model.accel``."""


def _format_2_to_3(config: dict[str, Any]) -> dict[str, Any]:
    """Format 2's saved data in format 3: ``field.zerorf`` (with ``enabled``) becomes ZeroRF's model config."""
    model = config.get("pipeline", {}).get("model", {})
    zerorf = model.get("field", {}).pop("zerorf", None)
    if isinstance(zerorf, dict) and zerorf.pop("enabled", False):
        model["_type"], model["zerorf"] = "ZeroRFModelConfig", zerorf
    accel = model.get("accel", {})
    if accel.get("backend") == "reference":
        accel["backend"] = "reference-grid-ops"
    return config


def _format_3_to_4(config: dict[str, Any]) -> dict[str, Any]:
    """Format 3's saved data in format 4: ``fourier.init_in_band`` at its default is dropped (a run that set it stays
    refused), and ZeroRF runs trained without the silhouette term resume and evaluate without it."""
    model = config.get("pipeline", {}).get("model", {})
    fourier = model.get("fourier", {})
    if fourier.get("init_in_band") is False:
        fourier.pop("init_in_band")
    if model.get("_type") == "ZeroRFModelConfig":
        model.setdefault("alpha_weight", 0.0)
    return config


UPGRADES: dict[int, Callable[[dict[str, Any]], dict[str, Any]]] = {2: _format_2_to_3, 3: _format_3_to_4}
"""Format N's saved data in format N + 1; ``load_config`` applies them in turn up to ``CONFIG_FORMAT``."""


@dataclasses.dataclass
class InstantiateConfig:
    """Base of every config: ``setup()`` returns ``_target(self, **kwargs)``."""

    # Set by subclasses with ``field(default_factory=lambda: Cls)``; hidden from the CLI and from JSON.
    _target: ClassVar[type | None] = None

    def setup(self, **kwargs: Any) -> Any:
        target = type(self)._target
        if target is None:
            raise TypeError(f"{type(self).__name__} has no _target to build")
        return target(self, **kwargs)


def config_classes() -> dict[str, type]:
    """Every config dataclass imported so far, by class name (subclasses of InstantiateConfig, recursively)."""
    found: dict[str, type] = {}
    stack: list[type] = [InstantiateConfig]
    while stack:
        cls = stack.pop()
        stack.extend(cls.__subclasses__())
        if dataclasses.is_dataclass(cls):
            found[cls.__name__] = cls
    return found


def to_dict(cfg: Any) -> Any:
    """A config tree as JSON-ready data; dataclasses carry their class name under ``_type``."""
    if dataclasses.is_dataclass(cfg) and not isinstance(cfg, type):
        out: dict[str, Any] = {"_type": type(cfg).__name__}
        for f in dataclasses.fields(cfg):
            if f.name.startswith("_"):
                continue
            out[f.name] = to_dict(getattr(cfg, f.name))
        return out
    if isinstance(cfg, Path):
        return str(cfg)
    if isinstance(cfg, (list, tuple)):
        return [to_dict(v) for v in cfg]
    if isinstance(cfg, dict):
        return {str(k): to_dict(v) for k, v in cfg.items()}
    if cfg is None or isinstance(cfg, (bool, int, float, str)):
        return cfg
    raise TypeError(f"cannot store {type(cfg).__name__} in a config: {cfg!r}")


Registry = Mapping[str, type]


def _convert(value: Any, tp: Any, where: str, registry: Registry) -> Any:
    """Convert JSON data to the annotated type ``tp`` (dataclasses, unions, paths, tuples, literals)."""
    origin = get_origin(tp)
    if tp is Any:
        return value
    if origin in (Union, types.UnionType):
        options = get_args(tp)
        if value is None and type(None) in options:
            return None
        if isinstance(value, dict) and "_type" in value:
            return _from_dict(value, where, registry)
        errors = []
        for opt in options:
            if opt is type(None):
                continue
            try:
                return _convert(value, opt, where, registry)
            except (TypeError, ValueError) as err:
                errors.append(str(err))
        raise ValueError(f"{where}: {value!r} matches none of {options}: {errors}")
    if origin is Literal:
        if value not in get_args(tp):
            raise ValueError(f"{where}: {value!r} is not one of {get_args(tp)}")
        return value
    if origin in (tuple, list):
        if not isinstance(value, list):
            raise TypeError(f"{where}: expected a list, got {value!r}")
        args = get_args(tp)
        if origin is tuple and args and args[-1] is not Ellipsis:
            if len(value) != len(args):
                raise ValueError(f"{where}: expected {len(args)} values, got {len(value)}: {value!r}")
            pairs = enumerate(zip(value, args, strict=True))
            return tuple(_convert(v, a, f"{where}[{i}]", registry) for i, (v, a) in pairs)
        item = args[0] if args else Any
        seq = [_convert(v, item, f"{where}[{i}]", registry) for i, v in enumerate(value)]
        return tuple(seq) if origin is tuple else seq
    if origin is dict:
        _, v_tp = get_args(tp) or (Any, Any)
        return {k: _convert(v, v_tp, f"{where}.{k}", registry) for k, v in value.items()}
    if dataclasses.is_dataclass(tp):
        if not isinstance(value, dict):
            raise TypeError(f"{where}: expected an object, got {value!r}")
        return _from_dict(value, where, registry, default_cls=tp)
    if tp is Path:
        if not isinstance(value, str):
            raise TypeError(f"{where}: expected a path string, got {value!r}")
        return Path(value)
    if tp is float:
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise TypeError(f"{where}: expected a number, got {value!r}")
        return float(value)
    if tp in (int, bool, str):
        if not isinstance(value, tp) or (tp is int and isinstance(value, bool)):
            raise TypeError(f"{where}: expected {tp.__name__}, got {value!r}")
        return value
    if tp is type(None):
        if value is not None:
            raise TypeError(f"{where}: expected null")
        return None
    raise TypeError(f"{where}: unsupported annotation {tp!r}")


def _from_dict(data: dict[str, Any], where: str, registry: Registry, default_cls: type | None = None) -> Any:
    name = data.get("_type")
    # Plain nested dataclasses (not InstantiateConfig) are known by their declared type only.
    known_plain = default_cls is not None and name == default_cls.__name__
    if name is not None and name not in registry and not known_plain:
        raise ValueError(f"{where}: unknown config class {name!r} (known: {sorted(registry)})")
    cls = registry.get(name, default_cls) if name is not None else default_cls
    if cls is None:
        raise ValueError(f"{where}: no config class given")
    if default_cls is not None and not issubclass(cls, default_cls):
        raise ValueError(f"{where}: {cls.__name__} is not a {default_cls.__name__}")
    hints = typing.get_type_hints(cls)
    kwargs: dict[str, Any] = {}
    names = {f.name for f in dataclasses.fields(cls) if not f.name.startswith("_")}
    unknown = set(data) - names - {"_type"}
    if unknown:
        raise ValueError(f"{where}: {cls.__name__} has no field(s) {sorted(unknown)}")
    for key, value in data.items():
        if key == "_type":
            continue
        kwargs[key] = _convert(value, hints[key], f"{where}.{key}", registry)
    return cls(**kwargs)


def from_dict(data: dict[str, Any], expected: type[C] | None = None, registry: Registry | None = None) -> C:
    """Rebuild a config tree saved by :func:`to_dict`; ``registry`` names the classes it may hold (default: every
    config class imported so far)."""
    cfg = _from_dict(data, "config", config_classes() if registry is None else registry, default_cls=expected)
    if expected is not None and not isinstance(cfg, expected):
        raise ValueError(f"config holds a {type(cfg).__name__}, expected {expected.__name__}")
    return cfg


def save_config(cfg: Any, path: Path) -> None:
    """Write ``config.json`` atomically (temp file + rename)."""
    payload = {"fourierf_version": __version__, "config_format": CONFIG_FORMAT, "config": to_dict(cfg)}
    write_text_atomic(path, json.dumps(payload, indent=2) + "\n")


def load_config(path: Path, expected: type[C] | None, registry: Registry) -> C:
    """Read a ``config.json`` whose classes are in ``registry``; every problem becomes one clear :class:`UserError`."""
    path = Path(path)
    check_reachable(path)
    if path.is_dir():
        path = path / "config.json"
    if not path.is_file():
        fail(
            f"config file not found: {path}",
            "pass the config.json written in a run directory (outputs/<scene>/<method>/<timestamp>/config.json)",
        )
    try:
        payload = json.loads(path.read_text())
    except (json.JSONDecodeError, UnicodeDecodeError) as err:
        fail(f"{path} is not valid JSON ({err})", "point at an untouched config.json written by fourierf-train")
    except RecursionError:
        fail(
            f"{path} nests its JSON too deeply to be read",
            "point at an untouched config.json written by fourierf-train",
        )
    if not isinstance(payload, dict) or "config" not in payload:
        fail(f"{path} is not a fourierf config (no 'config' key)", "point at a config.json written by fourierf-train")
    fmt = payload.get("config_format")
    config = payload["config"]
    while isinstance(fmt, int) and not isinstance(fmt, bool) and fmt in UPGRADES and isinstance(config, dict):
        config, fmt = UPGRADES[fmt](config), fmt + 1
    if fmt != CONFIG_FORMAT:
        fail(
            f"{path} uses config format {fmt!r} (fourierf {payload.get('fourierf_version')!r}); this is fourierf "
            f"{__version__}, which reads format {CONFIG_FORMAT}",
            "install the fourierf version that wrote it, or retrain with this version",
        )
    try:
        return from_dict(config, expected, registry)
    except (ValueError, TypeError, KeyError, RecursionError) as err:
        fail(
            f"{path} does not match this fourierf version's config: {err}",
            "retrain, or use the fourierf version that wrote it",
        )
