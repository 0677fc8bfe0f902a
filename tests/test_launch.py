"""The console scripts' launcher: a stop signal while the script loads ends the command with one line and no
traceback; once loaded, the script runs with the signals a plain Python process has."""

from __future__ import annotations

import signal
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

SLOW_SCRIPT = """
import signal, sys, time
print("loading", flush=True)
time.sleep(float(sys.argv[1]))

def entrypoint():
    print("default handler" if signal.getsignal(signal.SIGINT) is signal.default_int_handler else "other", flush=True)
"""


def _signals_as_in_a_terminal() -> None:
    """The child starts with SIGINT not ignored, as from a terminal: a job started in the background by a shell
    inherits it ignored, and Python then keeps it so."""
    signal.signal(signal.SIGINT, signal.SIG_DFL)


def start(tmp_path: Path, load_seconds: float) -> subprocess.Popen:
    (tmp_path / "slow_script.py").write_text(textwrap.dedent(SLOW_SCRIPT))
    code = "from fourierf_plugin.launch import launch; launch('slow_script', 'fourierf-slow')"
    return subprocess.Popen(
        [sys.executable, "-c", code, str(load_seconds)],
        cwd=tmp_path,
        env={"PYTHONPATH": f"{tmp_path}:{Path(__file__).resolve().parents[1]}"},
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        preexec_fn=_signals_as_in_a_terminal,
    )


@pytest.mark.parametrize("signum", [signal.SIGINT, signal.SIGTERM, signal.SIGHUP])
def test_a_stop_while_loading_is_one_line_and_the_signals_exit_code(tmp_path, signum):
    process = start(tmp_path, load_seconds=60)
    assert process.stdout.readline().strip() == "loading"
    process.send_signal(signum)
    _, err = process.communicate(timeout=30)
    assert process.returncode == 128 + signum
    assert err.strip() == f"fourierf-slow interrupted by {signal.Signals(signum).name} while starting; nothing written"


def test_the_loaded_script_runs_with_the_default_handlers(tmp_path):
    process = start(tmp_path, load_seconds=0)
    out, err = process.communicate(timeout=60)
    assert process.returncode == 0, err
    assert out.split() == ["loading", "default", "handler"]
