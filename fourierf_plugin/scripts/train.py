"""``fourierf-train METHOD [--flags] [blender-data [--parser-flags]]``: train (or resume) a run."""

from __future__ import annotations

import copy
import sys

import tyro

from fourierf_plugin.engine.option_checks import check_training_options
from fourierf_plugin.engine.trainer import Trainer, TrainerConfig
from fourierf_plugin.method_configs import AnnotatedMethodUnion, finalize, resume_config
from fourierf_plugin.method_configs.finalize import ignored_on_resume
from fourierf_plugin.method_configs.registry import HELP_REGISTRY
from fourierf_plugin.method_configs.time_budget import parse_duration
from fourierf_plugin.scripts.cli import run_cli, strip_verbose
from fourierf_plugin.scripts.observers import after_training, build_observers
from fourierf_plugin.utils.console import get_console
from fourierf_plugin.utils.errors import fail
from fourierf_plugin.utils.interrupt import stop_cleanly


def parse_args(args: list[str]) -> TrainerConfig:
    """The preset chosen by the first word, with every override applied (not yet finished: see ``build_config``)."""
    with HELP_REGISTRY:  # --help says which defaults the run sizes or the short-run rules set
        return copy.deepcopy(tyro.cli(AnnotatedMethodUnion, args=args))  # type: ignore[arg-type]


def given_options(args: list[str]) -> frozenset[str]:
    """Config paths of the flags in ``args`` (``--optimizer.weight-decay=0.2`` -> ``optimizer.weight_decay``), so that
    a value typed equal to the preset's own still wins over the scene preset, the run sizing and the budget rule."""
    flags = (arg[2:].split("=", 1)[0] for arg in args if arg.startswith("--") and len(arg) > 2)
    return frozenset(flag.replace("-", "_") for flag in flags)


def build_config(config: TrainerConfig, given: frozenset[str] = frozenset()) -> tuple[TrainerConfig, list[str]]:
    """The finished config of a new run (``finalize``, ``given`` the paths of the typed flags) or the saved one of a
    run to resume, and the notes to print."""
    if config.time_budget is not None:
        check_time_budget(config, given)
    if config.load_dir is not None:
        ignored = ignored_on_resume(config, given)
        if ignored:
            fail(
                f"{' '.join(ignored)} would be ignored: a resumed run continues with its own saved config "
                "(every schedule is a fraction of its length)",
                f"resume with only --load-dir {config.load_dir} (and --data if its scene moved, --threads, "
                "--device), or start a new run",
            )
        return resume_config(config.method_name, config.load_dir, config.data, config), []
    if config.data is None and str(config.pipeline.datamanager.dataparser.data) == ".":
        fail("no scene given", "pass --data PATH_TO_SCENE (e.g. --data demo/lego_tiny), or --load-dir RUN to resume")
    check_training_options(config)  # before any file of the scene is read
    return finalize(config, given)


def check_time_budget(config: TrainerConfig, given: frozenset[str]) -> None:
    """``--time-budget`` picks the iteration count of a new run: a UserError with ``--max-num-iterations``, on resume,
    or for a budget that is no duration."""
    if config.load_dir is not None:
        fail(
            f"--time-budget {config.time_budget} cannot resize a resumed run: it continues with its saved iteration "
            "count (every schedule is a fraction of it)",
            f"resume with only --load-dir {config.load_dir}, or start a new run with --time-budget",
        )
    if "max_num_iterations" in given:
        fail(
            f"--time-budget {config.time_budget} and --max-num-iterations {config.max_num_iterations} both set the "
            "run's length",
            "pass one of them: --time-budget picks the iteration count that fits the time",
        )
    parse_duration(config.time_budget)  # before any file of the scene is read


def main(args: list[str] | None = None) -> None:
    argv = strip_verbose(sys.argv[1:] if args is None else args)
    config, notes = build_config(parse_args(argv), given_options(argv))
    for note in notes:
        get_console().print(note, soft_wrap=True)
    observers = build_observers(config)
    try:
        Trainer(config, observers).train()
    except SystemExit as stop:
        after_training(observers, stop.code if isinstance(stop.code, int) else 1)
        raise
    after_training(observers, None)


def entrypoint() -> None:
    run_cli(stop_cleanly(main, "fourierf-train"))


if __name__ == "__main__":
    entrypoint()
