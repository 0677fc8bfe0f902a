"""Bad-input catalogue, the machine's part (issue 85): a symlink loop or an over-long name in a path flag, a full disk
while writing config.json, a checkpoint, eval.json, renders or a mesh, a second evaluation into the same outputs, and
Ctrl-C / SIGTERM at any moment of train, eval, render and export. Each ends with one clear message (exit 2, or 128 +
the signal for a stop) and no traceback, and leaves no half-written file or ``.partial`` folder behind.

Every case runs through the console scripts' own wrapping (``run_cli(stop_cleanly(main))``, what ``entrypoint``
does); a full disk is a write patched to fail with ENOSPC, a stop a real signal the process sends itself mid-work.
"""

from __future__ import annotations

import builtins
import errno
import os
import signal
import subprocess
import sys
import time
from collections.abc import Callable, Iterator
from pathlib import Path
from unittest import mock

import pytest
import trimesh

from fourierf_plugin.data.parsers.blender import BlenderDataParserConfig
from fourierf_plugin.data.parsers.nerfstudio import NerfstudioDataParserConfig
from fourierf_plugin.engine import checkpoint as checkpoint_module
from fourierf_plugin.engine import evaluation
from fourierf_plugin.engine import trainer as trainer_module
from fourierf_plugin.engine.checkpoint import list_checkpoints, load_checkpoint
from fourierf_plugin.exporter.marching_cubes import write_mesh
from fourierf_plugin.scripts import render as render_script
from fourierf_plugin.scripts.cli import EXIT_USER_ERROR, run_cli
from fourierf_plugin.utils import files
from fourierf_plugin.utils.files import run_renders_dir
from fourierf_plugin.utils.interrupt import STOP_SIGNALS, stop_cleanly
from tests.helpers import REPO_ROOT, TINY_SCENE, train_tiny
from tests.scripts.test_bad_inputs import (
    ENTRIES,
    EVAL,
    RENDER,
    blender,
    capture,
    edit_transforms,
    on_run,
    set_keys,
    train_on,
)

LONG = "n" * 300  # one path component over the 255 bytes file systems allow


@pytest.fixture(autouse=True)
def signals_restored() -> Iterator[None]:
    """A stopped command leaves the stop signals ignored (until its process ends); the test process gets them back."""
    saved = {s: signal.getsignal(s) for s in STOP_SIGNALS}
    yield
    for s, handler in saved.items():
        signal.signal(s, handler)


@pytest.fixture(scope="module")
def trained_config(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return train_tiny(tmp_path_factory.mktemp("run"), iters=6)[1] / "config.json"


def run_script(entry: str, args: list[str], capsys: pytest.CaptureFixture[str]) -> tuple[int, str]:
    """Run an entry point as its console script does (``sys.argv`` too); the exit code and stderr, unwrapped."""
    with pytest.raises(SystemExit) as info, mock.patch.object(sys, "argv", [f"fourierf-{entry}", *args]):
        run_cli(stop_cleanly(lambda: ENTRIES[entry](args), f"fourierf-{entry}"), args)
    return info.value.code, " ".join(capsys.readouterr().err.split())


def leftovers(root: Path) -> list[Path]:
    """Temporary siblings and partial folders anywhere under ``root``: what an interrupted write must not leave."""
    return [p for p in root.rglob("*") if ".partial" in p.name or ".tmp" in p.name or ".old-" in p.name]


def loop(tmp: Path) -> Path:
    """Two symbolic links pointing at each other."""
    (tmp / "loop_b").symlink_to(tmp / "loop_a")
    (tmp / "loop_a").symlink_to(tmp / "loop_b")
    return tmp / "loop_a"


# -- paths: symlink loops and over-long names ------------------------------------------------------------------------
PATH_CASES: dict[str, tuple[str, Callable[[Path, Path], list[str]], tuple[str, ...]]] = {
    "train: --data is a symlink loop": (
        "train",
        lambda tmp, _: train_on(loop(tmp), tmp),
        ("--data", "loop of symbolic links", "real folder"),
    ),
    "train: --data with a 300-byte name": (
        "train",
        lambda tmp, _: train_on(tmp / LONG, tmp),
        ("--data", "longer than the file system allows", "shorter"),
    ),
    "train: --output-dir is a symlink loop": (
        "train",
        lambda tmp, _: [*train_on(TINY_SCENE, tmp), "--output-dir", str(loop(tmp))],
        ("--output-dir", "loop of symbolic links"),
    ),
    "train: --output-dir with a 300-byte name": (
        "train",
        lambda tmp, _: [*train_on(TINY_SCENE, tmp), "--output-dir", str(tmp / LONG)],
        ("--output-dir", "longer than the file system allows"),
    ),
    "train: --load-dir is a symlink loop": (
        "train",
        lambda tmp, _: ["fourierf-vm", "--load-dir", str(loop(tmp))],
        ("--load-dir", "loop of symbolic links"),
    ),
    "train: --load-dir with a 300-byte name": (
        "train",
        lambda tmp, _: ["fourierf-vm", "--load-dir", str(tmp / LONG)],
        ("--load-dir", "longer than"),
    ),
    "eval: --output-path inside a symlink loop": (
        "eval",
        lambda tmp, cfg: ["--load-config", str(cfg), "--output-path", str(loop(tmp) / "e.json")],
        ("--output-path", "loop of symbolic links"),
    ),
    "eval: --output-path with a 300-byte name": (
        "eval",
        lambda tmp, cfg: ["--load-config", str(cfg), "--output-path", str(tmp / LONG / "e.json")],
        ("--output-path", "longer than the file system allows"),
    ),
}


@pytest.mark.parametrize("name", list(PATH_CASES))
def test_a_path_the_system_cannot_follow_is_one_clear_error(
    name: str, tmp_path: Path, trained_config: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    entry, build, expected = PATH_CASES[name]
    code, err = run_script(entry, build(tmp_path, trained_config), capsys)
    assert code == EXIT_USER_ERROR, err
    assert err.count("error:") == 1 and err.count("fix:") == 1 and "Traceback" not in err, err
    for text in expected:
        assert text in err, f"{text!r} missing from:\n{err}"


# -- a full disk -------------------------------------------------------------------------------------------------------
def fill_disk_on(monkeypatch: pytest.MonkeyPatch, owner: object, name: str, when: Callable[..., bool]) -> None:
    """``owner.name`` (a writer) raises ENOSPC when ``when(*args)`` holds, as a full disk would."""
    real = getattr(owner, name, getattr(builtins, name, None))  # a module's open() is the built-in one

    def full(*args: object, **kwargs: object) -> object:
        if when(*args):
            raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))
        return real(*args, **kwargs)

    monkeypatch.setattr(owner, name, full, raising=False)


def named(suffix: str) -> Callable[..., bool]:
    return lambda path, *rest: str(path).split(".tmp-")[0].endswith(suffix)


def always(*args: object) -> bool:
    return True


def full_at_config(mp: pytest.MonkeyPatch) -> None:
    fill_disk_on(mp, files, "open", named("config.json"))


def full_at_report(mp: pytest.MonkeyPatch) -> None:
    fill_disk_on(mp, files, "open", named("eval.json"))


DISK_CASES: dict[str, tuple[str, Callable[[Path, Path], list[str]], Callable[[pytest.MonkeyPatch], None], str]] = {
    "train: config.json": ("train", lambda tmp, _: train_on(TINY_SCENE, tmp), full_at_config, "config.json"),
    "eval: eval.json": ("eval", on_run(EVAL), full_at_report, "{tmp}/eval.json"),
    "eval: the renders": (
        "eval",
        on_run(["--load-config", "{config}", "--output-path", "{tmp}/eval.json", "--render-dir", "{tmp}/r"]),
        lambda mp: fill_disk_on(mp, evaluation.iio, "imwrite", always),
        "{tmp}/r",
    ),
    "render: the frames": (
        "render",
        on_run(RENDER),
        lambda mp: fill_disk_on(mp, render_script.iio, "imwrite", always),
        "{tmp}/r",
    ),
}


@pytest.mark.parametrize("name", list(DISK_CASES))
def test_a_full_disk_is_one_clear_error_and_leaves_nothing_half_written(
    name: str, tmp_path: Path, trained_config: Path, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    entry, build, fill, where = DISK_CASES[name]
    args = build(tmp_path, trained_config)
    fill(monkeypatch)
    code, err = run_script(entry, args, capsys)
    assert code == EXIT_USER_ERROR, err
    assert err.count("error:") == 1 and "Traceback" not in err, err
    assert "disk full at " in err and f"{where.format(tmp=tmp_path)}: nothing half-written was kept" in err, err
    assert "free space" in err
    assert not leftovers(tmp_path), leftovers(tmp_path)
    assert not (tmp_path / "eval.json").exists() and not (tmp_path / "mesh.ply").exists()
    assert not list(tmp_path.rglob("config.json")) and not list(tmp_path.rglob("*.png"))


def test_a_full_disk_at_a_checkpoint_stops_training_and_keeps_the_earlier_one(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    real_save = checkpoint_module.torch.save
    saves: list[int] = []

    def second_fails(obj: object, f: object, *args: object, **kwargs: object) -> None:
        saves.append(1)
        if len(saves) == 2:
            raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))
        real_save(obj, f, *args, **kwargs)

    monkeypatch.setattr(checkpoint_module.torch, "save", second_fails)
    code, err = run_script("train", train_on(TINY_SCENE, tmp_path, "--steps-per-save", "3", iters=9), capsys)
    assert code == EXIT_USER_ERROR and "Traceback" not in err, err
    (run_dir,) = [p.parent for p in tmp_path.rglob("config.json")]
    assert f"disk full at {run_dir / 'checkpoints'} (step-000000006.ckpt)" in err, err
    assert "step-000000003.ckpt is intact" in err and f"--load-dir {run_dir}" in err, err
    monkeypatch.undo()
    assert [p.name for p in list_checkpoints(run_dir / "checkpoints")] == ["step-000000003.ckpt"]
    assert load_checkpoint(run_dir / "checkpoints" / "step-000000003.ckpt")["step"] == 3
    assert not leftovers(tmp_path)


# -- two evaluations of one run at once ----------------------------------------------------------------------------
def test_a_second_evaluation_into_the_same_report_is_refused_by_pid(
    tmp_path: Path, trained_config: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    report = tmp_path / "eval.json"
    holder = subprocess.Popen(
        [sys.executable, "-c", "from fourierf_plugin.engine.run_dir import lock_output; "
         f"lock_output({str(report)!r}, '--output-path'); print('held', flush=True); import time; time.sleep(60)"],
        cwd=REPO_ROOT, stdout=subprocess.PIPE, text=True,
    )  # fmt: skip
    try:
        assert holder.stdout is not None and holder.stdout.readline().strip() == "held"
        code, err = run_script("eval", on_run(EVAL)(tmp_path, trained_config), capsys)
    finally:
        holder.kill()
        holder.wait()
    assert code == EXIT_USER_ERROR and "Traceback" not in err, err
    assert f"--output-path {report} is being written by process {holder.pid}" in err, err
    assert f"kill {holder.pid}" in err and "choose another --output-path" in err
    assert not report.exists()


def test_evaluations_started_together_claim_distinct_render_folders(tmp_path: Path) -> None:
    first = run_renders_dir(tmp_path, "test", 12, overwrite=False, claim=True)
    second = run_renders_dir(tmp_path, "test", 12, overwrite=False, claim=True)
    assert first != second and first.is_dir() and second.is_dir()
    assert second.name == f"{first.name}-1"


# -- a stop signal mid-work ----------------------------------------------------------------------------------------
def signal_after(monkeypatch: pytest.MonkeyPatch, owner: object, name: str, signum: int, calls: int = 1) -> None:
    """``owner.name`` works as before, and its ``calls``-th call then sends this process ``signum``."""
    real = getattr(owner, name)
    count = [0]

    def then_stop(*args: object, **kwargs: object) -> object:
        result = real(*args, **kwargs)
        count[0] += 1
        if count[0] == calls:
            os.kill(os.getpid(), signum)
        return result

    monkeypatch.setattr(owner, name, then_stop)


STOP_CASES: dict[str, tuple[str, Callable[[Path, Path], list[str]], Callable[[pytest.MonkeyPatch, int], None]]] = {
    "eval": (
        "eval",
        on_run(["--load-config", "{config}", "--output-path", "{tmp}/eval.json", "--render-dir", "{tmp}/r"]),
        lambda mp, s: signal_after(mp, evaluation.iio, "imwrite", s, calls=2),
    ),
    "render": (
        "render",
        on_run(["orbit", "--load-config", "{config}", "--output-dir", "{tmp}/r", "--n-frames", "6"]),
        lambda mp, s: signal_after(mp, render_script.iio, "imwrite", s, calls=4),
    ),
}


@pytest.mark.parametrize("signum", [signal.SIGINT, signal.SIGTERM], ids=["SIGINT", "SIGTERM"])
@pytest.mark.parametrize("name", list(STOP_CASES))
def test_a_stop_signal_mid_work_exits_cleanly_and_removes_the_partial_output(
    name: str,
    signum: int,
    tmp_path: Path,
    trained_config: Path,
    capsys: pytest.CaptureFixture[str],
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    entry, build, stop = STOP_CASES[name]
    args = build(tmp_path, trained_config)
    stop(monkeypatch, signum)
    code, err = run_script(entry, args, capsys)
    assert code == 128 + signum, err
    assert f"fourierf-{entry} interrupted by {signal.Signals(signum).name}; nothing written" in err, err
    assert "Traceback" not in err and "error:" not in err, err
    assert not leftovers(tmp_path), leftovers(tmp_path)
    assert not list(tmp_path.rglob("*.png")) and not list(tmp_path.rglob("*.gif"))
    assert not (tmp_path / "eval.json").exists() and not (tmp_path / "mesh.ply").exists()


def write_a_mesh(path: Path) -> Callable[[], None]:
    """What fourierf-export ends with, on a box: its field-sampling part is the same as any run's (see
    exporter/test_export.py); the write is where a full disk or a stop can leave a partial file."""
    return lambda: write_mesh(trimesh.creation.box(), path)


def test_export_on_a_full_disk_leaves_no_partial_mesh(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    fill_disk_on(monkeypatch, trimesh.Trimesh, "export", always)
    with pytest.raises(SystemExit) as info:
        run_cli(stop_cleanly(write_a_mesh(tmp_path / "mesh.ply"), "fourierf-export", []), [])
    err = " ".join(capsys.readouterr().err.split())
    assert info.value.code == EXIT_USER_ERROR and f"disk full at {tmp_path / 'mesh.ply'}" in err, err
    assert not list(tmp_path.iterdir())


@pytest.mark.parametrize("signum", [signal.SIGINT, signal.SIGTERM], ids=["SIGINT", "SIGTERM"])
def test_export_stopped_mid_write_leaves_no_partial_mesh(
    signum: int, tmp_path: Path, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    signal_after(monkeypatch, trimesh.Trimesh, "export", signum)  # the temporary file is written, then the stop
    with pytest.raises(SystemExit) as info:
        run_cli(stop_cleanly(write_a_mesh(tmp_path / "mesh.ply"), "fourierf-export", []), [])
    err = " ".join(capsys.readouterr().err.split())
    assert info.value.code == 128 + signum and "Traceback" not in err, err
    assert f"fourierf-export interrupted by {signal.Signals(signum).name}; nothing written" in err, err
    assert not list(tmp_path.iterdir())


def test_a_stop_before_the_first_step_exits_cleanly_naming_the_run(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    signal_after(monkeypatch, trainer_module, "make_run_dir", signal.SIGINT)
    code, err = run_script("train", train_on(TINY_SCENE, tmp_path, iters=30), capsys)
    (run_dir,) = [p for p in (tmp_path / "out").glob("*/*/*") if p.is_dir()]
    assert code == 130 and "Traceback" not in err, err
    assert f"fourierf-train interrupted by SIGINT; kept {run_dir}" in err, err
    assert not list_checkpoints(run_dir / "checkpoints")


def test_two_stop_signals_20_ms_apart_are_one_stop_that_saves(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    real_step = trainer_module.optimisation_step

    def step_then_double_tap(*args: object, **kwargs: object) -> object:
        result = real_step(*args, **kwargs)
        if args[3] == 2:  # the third step
            os.kill(os.getpid(), signal.SIGINT)
            time.sleep(0.02)
            os.kill(os.getpid(), signal.SIGINT)
        return result

    monkeypatch.setattr(trainer_module, "optimisation_step", step_then_double_tap)
    with pytest.raises(SystemExit) as info:
        run_cli(stop_cleanly(lambda: ENTRIES["train"](train_on(TINY_SCENE, tmp_path, iters=30)), "fourierf-train"))
    captured = capsys.readouterr()
    assert info.value.code == 130 and "Traceback" not in captured.err, captured.err
    assert "stopped by SIGINT at step 3: saved" in " ".join(captured.out.split())
    (ckpt,) = tmp_path.rglob("step-*.ckpt")
    assert load_checkpoint(ckpt)["step"] == 3


# -- accepted, with a warning ----------------------------------------------------------------------------------------
def test_a_principal_point_far_outside_the_image_is_named(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    root = capture(tmp_path, set_keys(cx=1e9))
    NerfstudioDataParserConfig(data=root).setup().get_outputs("train")
    err = " ".join(capsys.readouterr().err.split())
    assert "warning:" in err and str(root / "transforms.json") in err, err
    assert "principal point of frame_00000.png (and 9 more frames) lies outside its image (cx 1e+09" in err, err


def test_intrinsics_a_blender_file_gives_are_named_as_ignored(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    scene = edit_transforms(blender(tmp_path), "train", lambda meta: meta.update(cx=1e9, cy=50))
    BlenderDataParserConfig(data=scene).setup().get_outputs("train")
    err = " ".join(capsys.readouterr().err.split())
    assert "warning:" in err and str(scene / "transforms_train.json") in err, err
    assert "gives cx, cy (cx 1000000000.0, cy 50), which blender-data ignores" in err and "nerfstudio-data" in err
