"""The official code's betas: AdamW (0.9, 0.99) at first and (0.9, 0.98) at every rebuild after a reset
(``OptimizerConfig.betas_after_reset``), a function of the step, so a resumed run builds what its run had."""

from __future__ import annotations

from pathlib import Path

import pytest
import torch

from fourierf_plugin.engine.checkpoint import list_checkpoints
from fourierf_plugin.engine.optimizers import OptimizerConfig, betas_at, build_optimizer
from fourierf_plugin.engine.trainer import Trainer
from fourierf_plugin.method_configs import all_methods
from fourierf_plugin.scripts.train import build_config, parse_args
from tests.helpers import train_tiny

FIRST, AFTER = (0.9, 0.99), (0.9, 0.98)


def test_betas_switch_at_the_first_reset_and_stay() -> None:
    config = OptimizerConfig(betas=FIRST, betas_after_reset=AFTER)
    resets = [5, 9, 15]
    assert [betas_at(config, s, resets) for s in (0, 4)] == [FIRST, FIRST]
    assert [betas_at(config, s, resets) for s in (5, 6, 9, 15, 30)] == [AFTER] * 5
    assert betas_at(config, 100, []) == FIRST, "no reset, no switch"
    unset = OptimizerConfig(betas=FIRST)
    assert all(betas_at(unset, s, resets) == FIRST for s in (0, 5, 30)), "None: the same betas throughout"
    params = {"grids": [torch.nn.Parameter(torch.zeros(2))]}
    assert build_optimizer(config, params).param_groups[0]["betas"] == FIRST
    assert build_optimizer(config, params, 9, resets).param_groups[0]["betas"] == AFTER


def test_only_the_code_preset_switches() -> None:
    assert all_methods["fourierf-vm-code"].optimizer.betas == FIRST
    assert all_methods["fourierf-vm-code"].optimizer.betas_after_reset == AFTER
    assert all_methods["fourierf-vm"].optimizer.betas_after_reset is None


@pytest.mark.slow
def test_a_code_run_rebuilds_with_the_after_reset_betas_and_a_resume_past_it_keeps_them(
    tmp_path: Path, monkeypatch
) -> None:
    """20 iterations: occupancy updates after 4 and 8, upsamples after 6 and 14, so the rebuilt optimisers run from
    steps 5, 7, 9 and 15; a resume at step 10 is past the first reset."""
    import fourierf_plugin.engine.trainer as trainer_module

    built: list[tuple[int, torch.optim.Optimizer]] = []

    def recording(config, groups, step=0, reset_steps=()):
        optimizer = build_optimizer(config, groups, step, reset_steps)
        built.append((step, optimizer))
        return optimizer

    monkeypatch.setattr(trainer_module, "build_optimizer", recording)
    _, run_dir = train_tiny(tmp_path, "fourierf-vm-code", iters=20, extra=["--steps-per-save", "10"])
    assert [(s, o.param_groups[0]["betas"]) for s, o in built] == [(0, FIRST)] + [(s, AFTER) for s in (5, 7, 9, 15)]

    for ckpt in list_checkpoints(run_dir / "checkpoints"):
        if int(ckpt.stem.split("-")[1]) > 10:
            ckpt.unlink()
    built.clear()
    config, _ = build_config(parse_args(["fourierf-vm-code", "--load-dir", str(run_dir)]))
    resumed = Trainer(config)
    assert resumed.start_step == 10
    resumed.train()
    assert [(s, o.param_groups[0]["betas"]) for s, o in built] == [(10, AFTER), (15, AFTER)]
