"""``fourierf-viewer``'s bad inputs, each one clear message: no extra, no checkpoint, a newer config, a taken port."""

from __future__ import annotations

import json
import shutil
import socket
import sys
import time
from pathlib import Path

from fourierf_plugin.scripts.cli import EXIT_USER_ERROR
from fourierf_plugin.scripts.viewer import ViewerConfig, main, serve
from fourierf_plugin.viewer.server import MESH_EVERY_SECONDS
from tests.conftest import require_module
from tests.helpers import cli_exit_code

VISER_WHY = "the viewer needs viser (pip install '.[viewer]')"


def _copied_config(run_dir: Path, tmp: Path) -> Path:
    """The run's config.json in a new folder with an empty checkpoints/ (a run stopped before its first save)."""
    folder = tmp / "no-checkpoints"
    (folder / "checkpoints").mkdir(parents=True)
    return Path(shutil.copy(run_dir / "config.json", folder / "config.json"))


def test_without_viser_the_error_names_the_extra(trained_run, monkeypatch, capsys) -> None:
    _, run_dir = trained_run
    monkeypatch.setitem(sys.modules, "viser", None)  # import viser now raises ImportError
    assert cli_exit_code(main, ["--load-config", str(run_dir / "config.json")]) == EXIT_USER_ERROR
    err = capsys.readouterr().err
    assert "viser" in err and "pip install 'fourierf[viewer]'" in err
    assert "Traceback" not in err


def test_a_run_folder_without_checkpoints_is_one_clear_error(trained_run, tmp_path, capsys) -> None:
    require_module("viser", VISER_WHY)
    _, run_dir = trained_run
    config = _copied_config(run_dir, tmp_path)
    assert cli_exit_code(main, ["--load-config", str(config), "--port", "0"]) == EXIT_USER_ERROR
    err = capsys.readouterr().err
    assert "no checkpoints" in err and "train first" in err


def test_a_config_from_a_newer_version_says_so(trained_run, tmp_path, capsys) -> None:
    require_module("viser", VISER_WHY)
    _, run_dir = trained_run
    config = _copied_config(run_dir, tmp_path)
    payload = json.loads(config.read_text())
    payload.update(config_format=99, fourierf_version="9.0.0")
    config.write_text(json.dumps(payload))
    assert cli_exit_code(main, ["--load-config", str(config)]) == EXIT_USER_ERROR
    err = capsys.readouterr().err
    assert "config format 99" in err and "install the fourierf version" in err


def test_a_missing_config_and_bad_sizes_are_user_errors(tmp_path, capsys) -> None:
    require_module("viser", VISER_WHY)
    assert cli_exit_code(main, ["--load-config", str(tmp_path / "absent.json")]) == EXIT_USER_ERROR
    assert "config file not found" in capsys.readouterr().err
    config = tmp_path / "config.json"
    config.write_text("{}")
    args = ["--load-config", str(config), "--preview-side", "512", "--final-side", "256"]
    assert cli_exit_code(main, args) == EXIT_USER_ERROR
    assert "--preview-side" in capsys.readouterr().err


def test_a_port_in_use_moves_to_the_next_free_one_and_says_so(trained_run, capsys) -> None:
    require_module("viser", VISER_WHY)
    _, run_dir = trained_run
    with socket.socket() as taken:
        taken.bind(("127.0.0.1", 0))
        taken.listen()
        port = taken.getsockname()[1]
        handle = serve(ViewerConfig(load_config=run_dir / "config.json", port=port, host="127.0.0.1"))
        try:
            assert handle.port != port
            out = capsys.readouterr().out
            assert f"port {port} is in use" in out and str(handle.port) in out
        finally:
            handle.stop()


def test_the_mesh_button_writes_beside_earlier_meshes_without_overwriting(trained_run) -> None:
    require_module("viser", VISER_WHY)
    _, run_dir = trained_run
    handle = serve(ViewerConfig(load_config=run_dir / "config.json", port=0, host="127.0.0.1"))
    try:
        handle.view.density_slider.value = 0.5
        first = handle.view.export_mesh()
        handle.view.clock = lambda: time.perf_counter() + MESH_EVERY_SECONDS  # the next mesh is allowed
        second = handle.view.export_mesh()
    finally:
        handle.stop()
    assert first is not None, "the trained tiny run holds a surface at cutoff 0.5"
    assert first.parent == run_dir / "meshes" and first.name.startswith("viewer-f0.500")
    assert second is not None and second != first and second.exists() and first.exists()
