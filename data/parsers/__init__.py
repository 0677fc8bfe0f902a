"""Dataset-format parsers, installed as ``fourierf_plugin.data.parsers``.

``all_dataparsers`` maps the CLI subcommand name to a default config; third-party parsers join through the
``fourierf.dataparser_configs`` entry-point group (each entry point names a ``DataParserConfig`` instance).
"""

from __future__ import annotations

from importlib.metadata import entry_points

import tyro

from fourierf_plugin.data.dataparser_base import DataParserConfig
from fourierf_plugin.data.parsers.blender import BlenderDataParserConfig
from fourierf_plugin.data.parsers.colmap import ColmapDataParserConfig
from fourierf_plugin.data.parsers.llff import LLFFDataParserConfig
from fourierf_plugin.data.parsers.nerfstudio import NerfstudioDataParserConfig


def _discover() -> dict[str, DataParserConfig]:
    found: dict[str, DataParserConfig] = {
        "blender-data": BlenderDataParserConfig(),
        "llff-data": LLFFDataParserConfig(),
        "nerfstudio-data": NerfstudioDataParserConfig(),
        "colmap-data": ColmapDataParserConfig(),
    }
    for ep in entry_points(group="fourierf.dataparser_configs"):
        cfg = ep.load()
        if isinstance(cfg, DataParserConfig):
            found.setdefault(ep.name, cfg)
    return found


all_dataparsers = _discover()


def default_dataparser() -> DataParserConfig:
    return BlenderDataParserConfig()


DataParserUnion = tyro.conf.OmitSubcommandPrefixes[
    tyro.extras.subcommand_type_from_defaults(all_dataparsers, prefix_names=False)  # type: ignore[arg-type]
]
