"""The method registry: ``all_methods`` maps a CLI subcommand to a complete :class:`TrainerConfig`.

Third-party methods join through the ``fourierf.method_configs`` entry-point group; each entry point names a
``(TrainerConfig, description)`` pair.
"""

from __future__ import annotations

from importlib.metadata import entry_points

import tyro

from fourierf_plugin.engine.trainer import TrainerConfig
from fourierf_plugin.method_configs.presets import (
    descriptions,
    fourierf_cp,
    fourierf_vm,
    fourierf_vm_code,
    fourierf_vm_paper,
    tensorf_cp,
    tensorf_vm,
    zerorf_vm,
)

all_methods: dict[str, TrainerConfig] = {
    "fourierf-vm": fourierf_vm,
    "fourierf-cp": fourierf_cp,
    "fourierf-vm-paper": fourierf_vm_paper,
    "fourierf-vm-code": fourierf_vm_code,
    "tensorf-vm": tensorf_vm,
    "tensorf-cp": tensorf_cp,
    "zerorf-vm": zerorf_vm,
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
