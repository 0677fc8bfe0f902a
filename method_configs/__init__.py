"""Method presets and the layer that finishes a config, installed as ``fourierf_plugin.method_configs``.

``presets`` holds the built-in methods, ``registry`` adds the installed plugins' and builds the CLI's subcommands,
``finalize`` turns what a user typed into the config a trainer takes (scene preset, scene effects).
"""

from fourierf_plugin.method_configs.finalize import config_registry, finalize, resume_config
from fourierf_plugin.method_configs.registry import AnnotatedMethodUnion, all_descriptions, all_methods

__all__ = ["AnnotatedMethodUnion", "all_descriptions", "all_methods", "config_registry", "finalize", "resume_config"]
