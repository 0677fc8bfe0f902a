"""The console scripts' entry points: a stop signal during the seconds that loading the script (torch among it) takes
ends the command with one line and nothing written, before the script installs its own clean stop."""

from __future__ import annotations

import importlib
import os
import signal
import sys
from collections.abc import Callable

STOP_SIGNALS = tuple(getattr(signal, name) for name in ("SIGINT", "SIGTERM", "SIGHUP") if hasattr(signal, name))


def _stopped_while_loading(command: str) -> Callable[[int, object], None]:
    def handler(signum: int, frame: object) -> None:
        sys.stderr.write(f"{command} interrupted by {signal.Signals(signum).name} while starting; nothing written\n")
        sys.stderr.flush()
        os._exit(128 + signum)  # mid-import: no finaliser or half-loaded module may run

    return handler


def launch(module: str, command: str) -> None:
    """Load ``module`` with stop signals ending ``command`` quietly, then run its ``entrypoint`` with the signals as
    a plain Python process has them (the script installs its own clean stop)."""
    previous = {signum: signal.signal(signum, _stopped_while_loading(command)) for signum in STOP_SIGNALS}
    entrypoint = importlib.import_module(module).entrypoint
    for signum, handler in previous.items():
        signal.signal(signum, handler)
    entrypoint()


def _console_script(name: str) -> Callable[[], None]:
    """The entry point of ``fourierf-<name>`` (``fourierf_plugin.scripts.<name>``, dashes as underscores)."""

    def run() -> None:
        launch(f"fourierf_plugin.scripts.{name}", "fourierf-" + name.replace("_", "-"))

    return run


train = _console_script("train")
evaluate = _console_script("eval")
export = _console_script("export")
render = _console_script("render")
synth = _console_script("synth")
process_data = _console_script("process_data")
viewer = _console_script("viewer")
