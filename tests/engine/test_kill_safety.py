"""No run is ever lost (issue 6): SIGKILL at a random-ish moment, twice, then resume to the end.

A real ``fourierf-train`` subprocess saving every step is killed with SIGKILL at a seeded random delay after it wrote
a checkpoint; the newest checkpoint must load as-is (with ``torch.load(weights_only=True)`` and through
``load_latest_checkpoint``, without falling back), the resumed subprocess is killed again, and a final
``--load-dir`` resume must end exactly where an uninterrupted run with the same seed ends. Also here: names taken
from a dataset cannot make eval/render outputs escape the chosen folder or overwrite each other.

Covered elsewhere and not repeated: two runs started in the same second (engine/test_run_dir.py racing threads,
e2e/test_train_smoke.py fixed timestamp), Ctrl-C (engine/test_resume.py), disk-full/permission errors on save and
refusal of pickled objects (engine/test_checkpoint_io.py), config files being data only (configs/test_config_io.py).
"""

from __future__ import annotations

import json
import os
import random
import shutil
import signal
import subprocess
import time
from dataclasses import dataclass
from pathlib import Path

import pytest
import torch

from fourierf_plugin.engine.checkpoint import list_checkpoints, load_checkpoint, load_latest_checkpoint, save_checkpoint
from fourierf_plugin.engine.run_dir import MAX_NAME_LEN, unique_safe_name
from fourierf_plugin.field_components import schedules
from fourierf_plugin.scripts import eval as eval_script
from fourierf_plugin.scripts import render as render_script
from fourierf_plugin.scripts import train as train_script
from tests.helpers import (
    REPO_ROOT,
    TINY_SCENE,
    tiny_args,
    train_tiny,
    venv_script,
)

pytestmark = [pytest.mark.slow, pytest.mark.skipif(os.name == "nt", reason="SIGKILL is POSIX-only")]

ITERS = 60  # occupancy updates after 12 and 24, upsamples after 18 and 42: kills land around structure changes
FLAGS = ["--steps-per-save", "1", "--log-every", "1", "--threads", "1"]
MAX_STEPS_PER_LIFE = 20  # two lives of at most 20 steps past their first checkpoint stay well inside ITERS
KILL_SEED = 6  # the delays are random but reproducible; the exact step still depends on the machine's speed


@dataclass
class Kill:
    """What the run directory looked like right after one SIGKILL."""

    returncode: int
    newest: Path
    newest_step: int
    weights_only_step: int
    latest_step: int
    latest_path: Path


@dataclass
class KilledRun:
    run_dir: Path
    kills: list[Kill]
    stale_temp: Path


def _steps(run_dir: Path) -> list[int]:
    return [int(p.stem.split("-")[1]) for p in list_checkpoints(run_dir / "checkpoints")]


def _all_steps(out: Path) -> list[int]:
    """Checkpoint steps of every run under ``out`` (0 when there is none yet)."""
    return [0] + [s for run_dir in out.glob("*/*/*/") for s in _steps(run_dir)]


def _kill_after_a_new_checkpoint(args: list[str], out: Path, after_step: int, rng: random.Random, log: Path) -> Kill:
    """Run ``fourierf-train args``; once a checkpoint newer than ``after_step`` exists, wait a little and SIGKILL it."""
    script = venv_script("fourierf-train")
    if not script.exists():
        pytest.skip(f"{script} is not installed (pip install -e . first)")
    env = {**os.environ, "OMP_NUM_THREADS": "1", "COLUMNS": "200"}
    with log.open("w") as fh:
        proc = subprocess.Popen([str(script), *args], stdout=fh, stderr=subprocess.STDOUT, cwd=REPO_ROOT, env=env)
        try:
            deadline = time.monotonic() + 120
            while max(_all_steps(out)) <= after_step:
                assert proc.poll() is None, f"training ended before a checkpoint:\n{log.read_text()}"
                assert time.monotonic() < deadline, f"no checkpoint within 120 s:\n{log.read_text()}"
                time.sleep(0.02)
            # A random moment within 0.8 s, but never more than MAX_STEPS_PER_LIFE steps on, so a fast machine
            # cannot finish the run before the kill.
            kill_at = time.monotonic() + rng.uniform(0.0, 0.8)
            while time.monotonic() < kill_at and max(_all_steps(out)) < after_step + MAX_STEPS_PER_LIFE:
                time.sleep(0.005)
            proc.send_signal(signal.SIGKILL)
            proc.wait(timeout=60)
        finally:
            if proc.poll() is None:
                proc.kill()
                proc.wait()
    (run_dir,) = list(out.glob("*/*/*/"))
    newest = list_checkpoints(run_dir / "checkpoints")[-1]
    raw = torch.load(newest, map_location="cpu", weights_only=True)  # the newest file must load as it is
    latest_path, latest = load_latest_checkpoint(run_dir / "checkpoints")
    return Kill(proc.returncode, newest, _steps(run_dir)[-1], int(raw["step"]), int(latest["step"]), latest_path)


def _dead_pid() -> int:
    """The pid of a process that has exited (and been reaped)."""
    proc = subprocess.Popen(["true"])
    proc.wait()
    return proc.pid


@pytest.fixture(scope="module")
def killed(tmp_path_factory: pytest.TempPathFactory) -> KilledRun:
    """A run killed once while training and once while resuming; a killed writer's stale temp file is planted."""
    tmp = tmp_path_factory.mktemp("killed")
    out = tmp / "out"
    rng = random.Random(KILL_SEED)
    first = _kill_after_a_new_checkpoint(tiny_args(out, iters=ITERS, extra=FLAGS), out, 0, rng, tmp / "first.log")
    (run_dir,) = list(out.glob("*/*/*/"))
    resume_args = ["fourierf-vm", "--load-dir", str(run_dir)]
    second = _kill_after_a_new_checkpoint(resume_args, out, first.latest_step, rng, tmp / "second.log")
    stale = run_dir / "checkpoints" / f".step-{second.latest_step + 1:09d}.ckpt.tmp-{_dead_pid()}"
    stale.write_bytes(b"PK\x03\x04 half a checkpoint")
    return KilledRun(run_dir, [first, second], stale)


@pytest.fixture(scope="module")
def resumed(killed: KilledRun) -> KilledRun:
    """The killed run resumed in-process (``fourierf-train fourierf-vm --load-dir RUN``) to the end."""
    train_script.main(["fourierf-vm", "--load-dir", str(killed.run_dir)])
    return killed


@pytest.fixture(scope="module")
def uninterrupted(tmp_path_factory: pytest.TempPathFactory) -> Path:
    _, run_dir = train_tiny(tmp_path_factory.mktemp("whole"), iters=ITERS, extra=["--log-every", "1", "--threads", "1"])
    return run_dir


# -- SIGKILL ----------------------------------------------------------------------------------------------------------
def test_sigkill_leaves_the_newest_checkpoint_loadable(killed: KilledRun) -> None:
    first, second = killed.kills
    for kill in killed.kills:
        assert kill.returncode == -signal.SIGKILL, "the process was killed, not finished"
        assert 0 < kill.newest_step < ITERS
        assert kill.weights_only_step == kill.newest_step, "torch.load(weights_only=True) reads the newest file"
        assert kill.latest_path == kill.newest, "load_latest_checkpoint needed no fallback: no save was torn"
        assert kill.latest_step == kill.newest_step
    assert second.newest_step > first.newest_step, "the resumed process made progress before its own kill"


def test_resume_after_sigkill_ends_where_an_uninterrupted_run_ends(resumed: KilledRun, uninterrupted: Path) -> None:
    _, state = load_latest_checkpoint(resumed.run_dir / "checkpoints")
    assert state["step"] == ITERS
    _, reference = load_latest_checkpoint(uninterrupted / "checkpoints")
    ours, theirs = state["pipeline"]["model"], reference["pipeline"]["model"]
    assert ours.keys() == theirs.keys()
    for name, value in ours.items():
        assert value.shape == theirs[name].shape, name
        if value.is_floating_point():
            torch.testing.assert_close(value, theirs[name], atol=1e-5, rtol=0, msg=name)
        else:
            assert torch.equal(value, theirs[name]), name


def test_loss_curve_and_cutoff_schedule_continue_across_the_kills(resumed: KilledRun, uninterrupted: Path) -> None:
    """Every logged line parses; the run logs every step up to the end; a step logged twice (after its checkpoint
    was lost) has the same loss and cutoff both times; the values equal the uninterrupted run's."""
    lines = (resumed.run_dir / "metrics.jsonl").read_text().splitlines()
    records = [json.loads(line) for line in lines]  # a kill never leaves half a line
    assert records[-1]["event"] == "done" and records[-1]["step"] == ITERS
    logged = map(json.loads, (uninterrupted / "metrics.jsonl").read_text().splitlines())
    reference = {r["step"]: r for r in logged if "event" not in r}
    steps = [r["step"] for r in records if "event" not in r]
    assert sorted(set(steps)) == list(range(1, ITERS + 1))
    saved = json.loads((resumed.run_dir / "config.json").read_text())["config"]
    ramp = round(saved["pipeline"]["model"]["fourier"]["ramp_fraction"] * ITERS)  # the run's (the budget rule's)
    for r in records[:-1]:
        expected = reference[r["step"]]
        assert r["f_density"] == pytest.approx(schedules.cutoff_at(r["step"] - 1, 0.3, ramp))
        for key in ("loss", "psnr", "f_density", "f_color", "lr_scale", "rays"):
            assert r[key] == pytest.approx(expected[key], rel=1e-4, abs=1e-6), (r["step"], key)


def test_every_checkpoint_loads_with_weights_only(resumed: KilledRun) -> None:
    """A fourierf checkpoint is tensors and plain values only, so the safe loader reads all of them."""
    paths = list_checkpoints(resumed.run_dir / "checkpoints")
    assert paths
    for path in paths:
        state = torch.load(path, map_location="cpu", weights_only=True)
        assert {"step", "pipeline", "optimizer", "generator", "torch_rng"} <= set(state)
        assert load_checkpoint(path)["step"] == state["step"]


def test_a_killed_writers_temp_file_is_swept_on_the_next_save(resumed: KilledRun) -> None:
    assert not resumed.stale_temp.exists(), "a partial checkpoint of a dead process must not stay on disk for good"
    assert not list((resumed.run_dir / "checkpoints").glob(".step-*.tmp-*"))


def test_each_step_is_logged_once_after_a_resume(tmp_path: Path) -> None:
    """Deterministic stand-in for a kill between the metrics line of step 12 and its checkpoint."""
    _, run_dir = train_tiny(tmp_path, iters=12, extra=["--steps-per-save", "5", "--log-every", "1"])
    for path in list_checkpoints(run_dir / "checkpoints"):
        if int(path.stem.split("-")[1]) > 5:
            path.unlink()
    metrics = run_dir / "metrics.jsonl"
    metrics.write_text("".join(line + "\n" for line in metrics.read_text().splitlines() if '"event"' not in line))
    train_script.main(["fourierf-vm", "--load-dir", str(run_dir)])
    steps = [json.loads(line)["step"] for line in metrics.read_text().splitlines() if '"event"' not in line]
    assert steps == list(range(1, 13))


# -- names from the dataset -------------------------------------------------------------------------------------------
HOSTILE_NAMES = {
    # file_path in transforms_test.json -> the file holding its image
    "./test/..": "test/...png",
    "test/..\\..\\evil": "test/..\\..\\evil",
    "test/a:b": "test/a:b.png",
    "test/a?b": "test/a?b.png",
    "test/shot [final]": "test/shot [final].png",
}


def hostile_scene(root: Path) -> Path:
    """The bundled scene whose test frames are named ``..``, ``..\\.``, ``a:b``, ``a?b`` and ``shot [final]``."""
    scene = Path(shutil.copytree(TINY_SCENE, root / "hostile"))
    meta = json.loads((scene / "transforms_test.json").read_text())
    frames = meta["frames"][: len(HOSTILE_NAMES)]
    for frame, (file_path, image) in zip(frames, HOSTILE_NAMES.items(), strict=True):
        shutil.copy(scene / "test" / "r_0.png", scene / image)
        frame["file_path"] = file_path
    meta["frames"] = frames
    (scene / "transforms_test.json").write_text(json.dumps(meta))
    return scene


def _files(root: Path) -> set[Path]:
    return {p for p in root.rglob("*") if p.is_file()}


def test_dataset_names_cannot_escape_or_overwrite_outputs(
    uninterrupted: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    scene = hostile_scene(tmp_path)
    work = tmp_path / "work"
    work.mkdir()
    outside = tmp_path.parent
    before = _files(outside)
    config = str(uninterrupted / "config.json")
    eval_dir, render_dir = work / "eval_renders", work / "render"
    eval_args = ["--load-config", config, "--data", str(scene), "--output-path", str(work / "eval.json")]
    report = eval_script.main([*eval_args, "--render-dir", str(eval_dir)])
    render_args = ["dataset", "--load-config", config, "--data", str(scene), "--output-dir", str(render_dir)]
    render_script.main([*render_args, "--outputs", "rgb", "--no-video"])
    assert [p["name"] for p in report["per_image"]] == ["..", "..\\.", "a:b", "a?b", "shot [final]"]
    printed = capsys.readouterr().out
    assert "a:b: psnr" in printed and "shot [final]: psnr" in printed, "names are printed as they are"
    new = _files(outside) - before
    assert new, "something was written"
    for path in new:
        inside = path == work / "eval.json" or eval_dir in path.parents or render_dir in path.parents
        assert inside, f"{path} escaped the chosen output folders"
    assert not [p for p in _files(outside) if "evil" in p.name and scene not in p.parents]
    for folder in (eval_dir, render_dir / "rgb"):
        written = sorted(p.name for p in folder.iterdir())
        assert len(written) == len(HOSTILE_NAMES), f"renders overwrote each other in {folder}: {written}"


def test_unique_safe_names_never_collide_even_when_long() -> None:
    names = ["a:b", "a?b", "a_b_00002", "a/b", "x" * 300, "x" * 300 + "?", "..", "."]
    taken: set[str] = set()
    stems = [unique_safe_name(name, i, taken) for i, name in enumerate(names)]
    assert len(set(stems)) == len(names), stems
    assert all(len(s) <= MAX_NAME_LEN and "/" not in s and s not in (".", "..") for s in stems), stems


def test_the_sweep_spares_temp_files_of_live_processes(tmp_path: Path) -> None:
    live = tmp_path / f".step-000000002.ckpt.tmp-{os.getppid()}"
    dead = tmp_path / f".step-000000002.ckpt.tmp-{_dead_pid()}"
    for path in (live, dead):
        path.write_bytes(b"partial")
    save_checkpoint({"step": 1}, tmp_path, step=1)
    assert live.exists() and not dead.exists()
