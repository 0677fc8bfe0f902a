"""``fourierf-train METHOD [--flags] [blender-data [--parser-flags]]``: train (or resume) a run."""

from __future__ import annotations

import copy
import sys

import tyro

from fourierf_plugin.configs.option_checks import check_training_options
from fourierf_plugin.engine.trainer import Trainer, TrainerConfig
from fourierf_plugin.utils.errors import fail, run_cli, strip_verbose


def parse_args(args: list[str]) -> TrainerConfig:
    """The preset chosen by the first word, with every override applied (``--data`` lands in the parser)."""
    from fourierf_plugin.method_configs import AnnotatedMethodUnion

    config: TrainerConfig = copy.deepcopy(tyro.cli(AnnotatedMethodUnion, args=args))  # type: ignore[arg-type]
    if config.data is not None:
        config.pipeline.datamanager.dataparser.data = config.data
    return config


def main(args: list[str] | None = None) -> None:
    config = parse_args(strip_verbose(sys.argv[1:] if args is None else args))
    if config.load_dir is None:
        data = config.pipeline.datamanager.dataparser.data
        if config.data is None and str(data) == ".":
            fail(
                "no scene given", "pass --data PATH_TO_SCENE (e.g. --data demo/lego_tiny), or --load-dir RUN to resume"
            )
    check_training_options(config)  # before anything is built or a run directory is made
    Trainer(config).train()


def entrypoint() -> None:
    run_cli(main)


if __name__ == "__main__":
    entrypoint()
