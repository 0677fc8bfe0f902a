"""Tiny training settings shared by the CLI, smoke and resume tests: the bundled scene on a 16³ -> 24³ grid.

Why one place: every end-to-end test must stay a few seconds on two shared CPU cores, and a change of the demo
scene or of a flag name should be fixed once, not in five files.
"""

from __future__ import annotations

import importlib.util
import sys
from collections.abc import Callable
from pathlib import Path
from types import ModuleType

import pytest
import torch

from fourierf_plugin.data.parsers.blender import BLENDER_DECLARATION
from fourierf_plugin.data.parsers.llff import LLFF_DECLARATION, NDC_BOX
from fourierf_plugin.data.scene_effects import SceneEffects
from fourierf_plugin.engine.checkpoint import list_checkpoints, load_latest_checkpoint
from fourierf_plugin.engine.trainer import Trainer, TrainerConfig
from fourierf_plugin.fields.fourier_tensorf_field import FieldConfig
from fourierf_plugin.model_components.rendering import accumulate
from fourierf_plugin.models.fourierf import FourieRFModel, FourieRFModelConfig
from fourierf_plugin.scripts import export as export_script
from fourierf_plugin.scripts import render as render_script
from fourierf_plugin.scripts.cli import run_cli
from fourierf_plugin.scripts.eval import EvalConfig, run_eval
from fourierf_plugin.scripts.train import build_config, parse_args

REPO_ROOT = Path(__file__).resolve().parents[1]
TINY_SCENE = REPO_ROOT / "demo" / "lego_tiny"
TINY_TRAIN_IDS = [0, 1, 2, 3]  # indices into the demo's transforms_train.json frames
TINY_TRAIN_NAMES = ["r_27", "r_76", "r_97", "r_99"]
TINY_TEST_VIEWS = 8
TINY_IMAGE_SIZE = (100, 100)
TINY_INIT_RESO = [16, 16, 16]  # n_voxels_init 4096 in the cubic Blender box
TINY_FINAL_RESO = [24, 24, 24]  # n_voxels_final 13824

TINY_FLAGS: list[str] = [
    "--pipeline.datamanager.rays-per-batch",
    "256",
    "--pipeline.model.field.n-voxels-init",
    "4096",
    "--pipeline.model.field.n-voxels-final",
    "13824",
]
"""Overrides that make a run take seconds: 256 rays a batch, a 16³ grid upsampled to 24³."""


def tiny_args(
    output_dir: Path, method: str = "fourierf-vm", iters: int = 30, extra: list[str] | None = None
) -> list[str]:
    """``fourierf-train`` arguments for a tiny run on the bundled scene writing under ``output_dir``."""
    return [
        method,
        "--data",
        str(TINY_SCENE),
        "--output-dir",
        str(output_dir),
        "--max-num-iterations",
        str(iters),
        *TINY_FLAGS,
        *(extra or []),
    ]


def tiny_trainer_config(
    output_dir: Path, method: str = "fourierf-vm", iters: int = 30, extra: list[str] | None = None
) -> TrainerConfig:
    """The finished config of a tiny run (built through the real CLI parser and ``finalize``)."""
    config, _ = build_config(parse_args(tiny_args(output_dir, method, iters, extra)))
    return config


def train_tiny(
    output_dir: Path, method: str = "fourierf-vm", iters: int = 30, extra: list[str] | None = None
) -> tuple[Trainer, Path]:
    """Train a tiny run in-process; returns the trainer (for its final model) and the run directory."""
    trainer = Trainer(tiny_trainer_config(output_dir, method, iters, extra))
    run_dir = trainer.train()
    return trainer, run_dir


def cli_exit_code(main: Callable[[list[str]], object], args: list[str]) -> int:
    """Run a console script's ``main(args)`` the way its entry point does (under ``run_cli``) and return the exit
    code it ends with; a run that ends without exiting fails the test."""
    with pytest.raises(SystemExit) as info:
        run_cli(lambda: main(args), args)
    return info.value.code


def cli_outcome(main: Callable[[list[str]], object], args: list[str]) -> int:
    """The exit code of a console script's ``main(args)`` run the way its entry point does: 0 when it returns, the
    code it exits with otherwise (for commands whose success and clear failure are both acceptable outcomes)."""
    try:
        run_cli(lambda: main(args), args)
    except SystemExit as end:
        return int(end.code or 0)
    return 0


class FakeClock:
    """A clock that stands still until told (``clock.now += 2``), to monkeypatch over ``time.perf_counter``; it
    counts how often it was read."""

    def __init__(self, now: float = 1000.0) -> None:
        self.now = now
        self.reads = 0

    def __call__(self) -> float:
        self.reads += 1
        return self.now


def venv_script(name: str) -> Path:
    """An installed console script of the interpreter running the tests (``.venv/bin/fourierf-train``)."""
    return Path(sys.executable).parent / name


def ndc_model(
    config: FourieRFModelConfig, max_iters: int = 100, effects: SceneEffects = LLFF_DECLARATION
) -> FourieRFModel:
    """A model on the LLFF NDC box with the LLFF effects (seeded), for NDC sampler and effects tests."""
    return config.setup(
        scene_box=torch.tensor(NDC_BOX),
        near=0.0,
        far=1.0,
        effects=effects,
        max_iters=max_iters,
        generator=torch.Generator().manual_seed(0),
    )


BLENDER = BLENDER_DECLARATION


def slab_model(slab_density: float, **config) -> FourieRFModel:
    """A 16³ ReLU field with σ = ``slab_density`` for z in the middle third of the box, 0 elsewhere."""
    field = FieldConfig(
        n_voxels_init=16**3, density_components=(2, 2, 2), appearance_components=(3, 3, 3), appearance_dim=6,
        hidden_dim=16, density_activation="relu",
    )  # fmt: skip
    torch.manual_seed(0)  # the decoder's layers draw from the global generator
    model = FourieRFModelConfig(field=field, **config).setup(
        scene_box=torch.tensor([[-1.5] * 3, [1.5] * 3]), near=0.5, far=6.0, effects=BLENDER, max_iters=10,
        generator=torch.Generator().manual_seed(0),
    )  # fmt: skip
    grid = model.field.density_grid
    with torch.no_grad():
        for p in [*grid.planes, *grid.lines]:
            p.zero_()
        grid.planes[0][0].fill_(1.0)  # the xy plane times the z line
        z = grid.lines[0].shape[1]
        grid.lines[0][0, z // 3 : 2 * z // 3] = slab_density
    model.field.invalidate()
    return model


def rays_through_the_slab(n: int = 64) -> tuple[torch.Tensor, torch.Tensor]:
    g = torch.Generator().manual_seed(1)
    origins = torch.cat([torch.rand(n, 2, generator=g) - 0.5, torch.full((n, 1), -3.0)], dim=-1)
    directions = torch.cat([(torch.rand(n, 2, generator=g) - 0.5) * 0.2, torch.ones(n, 1)], dim=-1)
    return origins, directions / directions.norm(dim=-1, keepdim=True)


def accumulate_rays(weights: torch.Tensor, values: torch.Tensor) -> torch.Tensor:
    """Dense [R, N] weights and [R, N, C] values through the packed ``accumulate`` (every sample listed)."""
    num_rays, num_samples = weights.shape
    rays = torch.arange(num_rays).repeat_interleave(num_samples)
    return accumulate(weights.reshape(-1), values.reshape(-1, values.shape[-1]), rays, num_rays)


def load_benchmark(name: str) -> ModuleType:
    """Import ``benchmarks/<name>.py`` (a script, not a package module) so its pure functions can be tested."""
    path = Path(__file__).resolve().parents[1] / "benchmarks" / f"{name}.py"
    spec = importlib.util.spec_from_file_location(name, path)
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module  # its dataclasses look their module up there
    spec.loader.exec_module(module)
    return module


def resumed_and_uninterrupted(
    tmp_path: Path, method: str, iters: int, resume_at: int, flags: list[str]
) -> tuple[Trainer, Trainer]:
    """Two identical tiny runs of ``method`` saving every ``resume_at`` steps; the second, its checkpoints after
    ``resume_at`` deleted, resumed to the end as ``fourierf-train METHOD --load-dir RUN`` does: (the uninterrupted
    trainer, the resumed one)."""
    flags = [*flags, "--steps-per-save", str(resume_at), "--keep-checkpoints", str(iters)]
    uninterrupted, _ = train_tiny(tmp_path / "a", method, iters, flags)
    _, run_b = train_tiny(tmp_path / "b", method, iters, flags)
    for ckpt in list_checkpoints(run_b / "checkpoints"):
        if int(ckpt.stem.split("-")[1]) > resume_at:
            ckpt.unlink()
    assert load_latest_checkpoint(run_b / "checkpoints")[1]["step"] == resume_at
    config, _ = build_config(parse_args([method, "--load-dir", str(run_b)]))
    resumed = Trainer(config)
    assert resumed.start_step == resume_at
    resumed.train()
    return uninterrupted, resumed


def assert_same_model_state(a: Trainer, b: Trainer) -> None:
    """The two trainers' models hold the same tensors (floats to 1e-5)."""
    state_a, state_b = a.pipeline.model.state_dict(), b.pipeline.model.state_dict()
    assert state_a.keys() == state_b.keys()
    for name, value in state_b.items():
        if value.is_floating_point():
            torch.testing.assert_close(value, state_a[name], atol=1e-5, rtol=1e-5, msg=name)
        else:
            assert torch.equal(value, state_a[name]), name


def evaluate_render_and_export(config_path: Path, out: Path) -> dict:
    """fourierf-eval (no renders saved), a two-frame orbit and a 16³ mesh of a saved run; returns the evaluation's
    report (the orbit's frames and the mesh are checked here)."""
    report = run_eval(
        EvalConfig(load_config=config_path, output_path=out / "eval.json", render_dir=Path("none"), device="cpu")
    )
    render_script.main(
        ["orbit", "--load-config", str(config_path), "--output-dir", str(out / "orbit"), "--n-frames", "2",
         "--resolution-scale", "0.25", "--outputs", "rgb", "--no-video"]
    )  # fmt: skip
    assert len(list((out / "orbit").rglob("*.png"))) == 2
    mesh = out / "mesh.ply"
    export_script.main(
        ["marching-cubes", "--load-config", str(config_path), "--resolution", "16", "--output-path", str(mesh)]
    )
    assert mesh.is_file() and mesh.stat().st_size > 0
    return report
