"""The method registry: ``all_methods`` maps a CLI subcommand to a complete :class:`TrainerConfig`.

Third-party methods join through the ``fourierf.method_configs`` entry-point group; each entry point names a
``(TrainerConfig, description)`` pair.
"""

from __future__ import annotations

import threading
from collections.abc import Callable, Iterable
from dataclasses import replace
from importlib.metadata import entry_points
from typing import Annotated

import tyro
import tyro.constructors

from fourierf_plugin.engine.trainer import TrainerConfig
from fourierf_plugin.method_configs.budget import RULES
from fourierf_plugin.method_configs.presets import (
    descriptions,
    fourierf_cp,
    fourierf_vm,
    fourierf_vm_code,
    fourierf_vm_paper,
    freenerf,
    tensorf_cp,
    tensorf_vm,
    tensorf_vm_published,
    zerorf_vm,
)
from fourierf_plugin.method_configs.sizing import SIZED_PATHS

all_methods: dict[str, TrainerConfig] = {
    "fourierf-vm": fourierf_vm,
    "fourierf-cp": fourierf_cp,
    "fourierf-vm-paper": fourierf_vm_paper,
    "fourierf-vm-code": fourierf_vm_code,
    "tensorf-vm": tensorf_vm,
    "tensorf-cp": tensorf_cp,
    "tensorf-vm-published": tensorf_vm_published,
    "zerorf-vm": zerorf_vm,
    "freenerf": freenerf,
}
all_descriptions: dict[str, str] = dict(descriptions)

for _ep in entry_points(group="fourierf.method_configs"):
    _spec = _ep.load()
    if isinstance(_spec, tuple) and len(_spec) == 2 and isinstance(_spec[0], TrainerConfig):
        all_methods.setdefault(_ep.name, _spec[0])
        all_descriptions.setdefault(_ep.name, str(_spec[1]))

AnnotatedMethodUnion = tyro.conf.SuppressFixed[
    tyro.conf.FlagConversionOff[tyro.extras.subcommand_type_from_defaults(all_methods, all_descriptions)]  # type: ignore[arg-type]
]


def _field_owners(paths: Iterable[str]) -> set[tuple[type, str]]:
    """(config class, field name) of each config path, found along ``fourierf-vm``'s tree."""
    owners = set()
    for path in paths:
        *parents, leaf = path.split(".")
        node: object = fourierf_vm
        for part in parents:
            node = getattr(node, part)
        owners.add((type(node), leaf))
    return owners


SIZED = _field_owners(SIZED_PATHS)
SHORT_RUN = _field_owners(path for rule in RULES for path in rule.settings) - SIZED
HELP_REGISTRY = tyro.constructors.ConstructorRegistry()
"""Activate around ``tyro.cli`` (``with HELP_REGISTRY:``): ``--help`` then says which defaults a run decides for itself
(the run size, the short-run defaults) instead of showing only the preset's value."""
_deferring = threading.local()


@HELP_REGISTRY.struct_rule
def _help_hints(info: tyro.constructors.StructTypeInfo) -> tyro.constructors.StructConstructorSpec | None:
    """tyro's own spec for a config class, its sized and short-run fields annotated with what decides them."""
    owned = {name for cls, name in SIZED | SHORT_RUN if info.type is cls}
    if not owned or getattr(_deferring, "active", False):
        return None
    _deferring.active = True
    try:
        spec = tyro.constructors.ConstructorRegistry.get_struct_spec(info)
    finally:
        _deferring.active = False
    if not isinstance(spec, tyro.constructors.StructConstructorSpec):
        return None
    fields = tuple(
        replace(field, type=Annotated[field.type, tyro.conf.arg(help_behavior_hint=_hint(info.type, field.name))])
        if field.name in owned
        else field
        for field in spec.fields
    )
    return replace(spec, fields=fields)


def _hint(cls: type, name: str) -> Callable[[str], str]:
    if (cls, name) in SIZED:
        return lambda default: f"(default: auto (sized to the scene and the device); the preset's: {default})"
    return lambda default: f"(default: {default}, or a short-run default: docs/defaults.md)"
