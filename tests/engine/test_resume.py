"""Checkpoints restore a run exactly: structure after upsample/shrink, the full training state, and Ctrl-C saves."""

from __future__ import annotations

import os
import signal
import subprocess
import time
from pathlib import Path

import pytest
import torch

from fourierf_plugin.configs.base import load_config
from fourierf_plugin.engine.checkpoint import list_checkpoints, load_latest_checkpoint
from fourierf_plugin.engine.trainer import Trainer, TrainerConfig
from fourierf_plugin.method_configs import config_registry
from fourierf_plugin.pipelines.base import Pipeline
from fourierf_plugin.scripts.train import build_config, parse_args
from fourierf_plugin.utils.errors import UserError
from tests.helpers import (
    REPO_ROOT,
    TINY_FINAL_RESO,
    tiny_args,
    train_tiny,
    venv_script,
)

pytestmark = pytest.mark.slow

# One late occupancy update (step 24 of 30, after the upsamples at 9 and 21) with a threshold low enough for the
# few trained iterations to mark some cells occupied, so the first update really shrinks the box and crops the grid.
# The preset's optimiser (no budget rule) gives the density these 30 iterations grow: the shrink depends on it.
SHRINK_FLAGS = [
    "--pipeline.model.occupancy-update-fractions", "0.8", "--pipeline.model.occupancy-threshold", "2e-5",
    "--budget-rule", "False",
]  # fmt: skip


def _fresh_pipeline(run_dir: Path) -> tuple[Pipeline, int]:
    """A pipeline rebuilt from the run's config.json with its latest checkpoint loaded (what fourierf-eval does)."""
    config = load_config(run_dir / "config.json", TrainerConfig, config_registry())
    pipeline: Pipeline = config.pipeline.setup(
        device=torch.device("cpu"), max_iters=config.max_num_iterations, generator=torch.Generator().manual_seed(0)
    )
    _, state = load_latest_checkpoint(run_dir / "checkpoints")
    pipeline.load_state_dict(state["pipeline"])
    return pipeline, int(state["step"])


def test_checkpoint_restores_a_model_after_upsample_and_shrink(tmp_path: Path) -> None:
    iters = 30
    trainer, run_dir = train_tiny(tmp_path, iters=iters, extra=SHRINK_FLAGS)
    trained = trainer.pipeline.model
    full_box = torch.tensor([[-1.5] * 3, [1.5] * 3])
    assert not torch.equal(trained.aabb, full_box), "precondition: the occupancy update shrank the box"
    assert trained.field.resolution != TINY_FINAL_RESO, "precondition: the shrink cropped the upsampled grid"
    assert trained.occupancy.active

    pipeline, step = _fresh_pipeline(run_dir)
    model = pipeline.model
    assert step == iters
    assert model.field.resolution == trained.field.resolution
    assert torch.equal(model.aabb, trained.aabb)
    assert torch.equal(model.occupancy.cells, trained.occupancy.cells)
    assert torch.equal(pipeline.datamanager.active, trainer.pipeline.datamanager.active)
    trained_state = trained.state_dict()
    for name, value in model.state_dict().items():
        assert torch.equal(value, trained_state[name]), name

    rays = trainer.pipeline.datamanager.train_rays
    assert rays is not None
    pick = torch.linspace(0, rays.origins.shape[0] - 1, 64).long()
    a = trained.render_rays(rays.origins[pick], rays.directions[pick], iters)
    b = model.render_rays(rays.origins[pick], rays.directions[pick], iters)
    for key in ("rgb", "accumulation", "depth"):
        assert torch.equal(a[key], b[key]), key
    assert float(a["accumulation"].max()) > 0, "the render is not trivially empty"


def _resume(method: str, run_dir: Path) -> Trainer:
    """A trainer resuming ``run_dir`` as ``fourierf-train METHOD --load-dir RUN`` builds it (the saved config)."""
    config, notes = build_config(parse_args([method, "--load-dir", str(run_dir)]))
    assert notes == [], "a resumed run decides nothing again: its saved config is finished"
    return Trainer(config)


def test_resumed_run_ends_where_an_uninterrupted_run_ends(tmp_path: Path) -> None:
    """Occupancy updates at 8 and 16 (ray filtering), upsamples at 12 and 28: resuming at 20 crosses one of each."""
    flags = ["--steps-per-save", "10", "--keep-checkpoints", "10", "--log-every", "1"]
    trainer_a, _ = train_tiny(tmp_path / "a", iters=40, extra=flags)
    _, run_b = train_tiny(tmp_path / "b", iters=40, extra=flags)

    for ckpt in list_checkpoints(run_b / "checkpoints"):
        if int(ckpt.stem.split("-")[1]) > 20:
            ckpt.unlink()
    assert load_latest_checkpoint(run_b / "checkpoints")[1]["step"] == 20

    resumed = _resume("fourierf-vm", run_b)
    assert resumed.config.pipeline.effects.is_resolved
    assert resumed.start_step == 20
    assert resumed.run_dir == run_b
    assert resumed.train() == run_b

    state_a = trainer_a.pipeline.model.state_dict()
    state_b = resumed.pipeline.model.state_dict()
    assert state_a.keys() == state_b.keys()
    for name, value in state_b.items():
        assert value.shape == state_a[name].shape, name
        if value.is_floating_point():
            assert torch.allclose(value, state_a[name], atol=1e-5), name
        else:
            assert torch.equal(value, state_a[name]), name
    assert torch.equal(resumed.pipeline.datamanager.active, trainer_a.pipeline.datamanager.active)
    assert load_latest_checkpoint(run_b / "checkpoints")[1]["step"] == 40


def test_resume_with_another_method_is_refused(tmp_path: Path) -> None:
    _, run_dir = train_tiny(tmp_path, iters=10)
    with pytest.raises(UserError) as info:
        _resume("tensorf-vm", run_dir)
    assert "fourierf-vm" in info.value.problem and "--load-dir" in (info.value.fix or "")


def _wait_for(predicate, timeout: float, proc: subprocess.Popen) -> bool:
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if predicate():
            return True
        if proc.poll() is not None:
            return False
        time.sleep(0.1)
    return False


@pytest.mark.skipif(os.name == "nt", reason="signals to a child process are POSIX-only")
@pytest.mark.parametrize(("signum", "exit_code"), [(signal.SIGINT, 130), (signal.SIGTERM, 143), (signal.SIGHUP, 129)])
def test_a_stop_signal_saves_a_checkpoint_and_exits_128_plus_its_number(
    tmp_path: Path, signum: signal.Signals, exit_code: int
) -> None:
    """Ctrl-C, and SIGTERM/SIGHUP (a scheduler, ``timeout``, a closed SSH session, a container stop) finish the step,
    save a checkpoint, print how to resume and exit with the shell's code for the signal."""
    script = venv_script("fourierf-train")
    if not script.exists():
        pytest.skip(f"{script} is not installed (pip install -e . first)")
    total = 2000
    out = tmp_path / "out"
    args = tiny_args(out, iters=total, extra=["--steps-per-save", "100000", "--log-every", "1", "--threads", "1"])
    stdout_path, stderr_path = tmp_path / "stdout.txt", tmp_path / "stderr.txt"
    env = {**os.environ, "COLUMNS": "200", "OMP_NUM_THREADS": "1"}
    with stdout_path.open("w") as stdout, stderr_path.open("w") as stderr:
        proc = subprocess.Popen([str(script), *args], stdout=stdout, stderr=stderr, cwd=REPO_ROOT, env=env)
        try:
            started = _wait_for(lambda: any(out.glob("*/*/*/metrics.jsonl")), 120, proc)
            assert started, f"training never started:\n{stdout_path.read_text()}\n{stderr_path.read_text()}"
            proc.send_signal(signum)
            code = proc.wait(timeout=60)
        finally:
            if proc.poll() is None:
                proc.kill()
                proc.wait()
    text, err = stdout_path.read_text(), stderr_path.read_text()
    assert code == exit_code, f"exit code {code}\n{text}\n{err}"
    assert "Traceback" not in err
    assert f"stopped by {signum.name}" in text and "resume with" in text and "--load-dir" in text

    (run_dir,) = list(out.glob("*/*/*/"))
    _, state = load_latest_checkpoint(run_dir / "checkpoints")
    assert 0 < state["step"] < total
    assert {"pipeline", "optimizer", "generator", "torch_rng"} <= set(state)
