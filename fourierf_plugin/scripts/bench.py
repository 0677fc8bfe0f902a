"""``fourierf-bench --data SCENE --methods fourierf-vm tensorf-vm --iters 400 800``: what accuracy costs in time.

Trains every combination of methods and knob values, evaluates each run at checkpoints along its budget and writes
``measurements.csv``, ``runs.jsonl``, ``report.md`` and plots into a new folder under ``--output-dir``.
"""

from __future__ import annotations

import shlex
import sys
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Literal

import tyro

from fourierf_plugin.bench import coordinator
from fourierf_plugin.bench.executors import LocalExecutor, RayExecutor, threads_per_worker
from fourierf_plugin.bench.runner import RunResult, RunTask, Scene, SceneKind
from fourierf_plugin.bench.sweep import (
    ProfileMode,
    RunSpec,
    SweepSpec,
    designate_profiled,
    expand,
    fourier_defaults,
    known_methods,
)
from fourierf_plugin.bench.sweep import merge as merge_runs
from fourierf_plugin.scripts.cli import run_cli, strip_verbose
from fourierf_plugin.utils.console import format_duration, get_console, warn
from fourierf_plugin.utils.errors import fail
from fourierf_plugin.utils.lpips import default_lpips_weights


@dataclass
class BenchConfig:
    data: Path
    """Scene folder: Blender (transforms_*.json), LLFF (poses_bounds.npy), a nerfstudio capture (transforms.json) or
    a COLMAP model (colmap/sparse/0, sparse/0)."""
    methods: tuple[str, ...] = ("fourierf-vm", "tensorf-vm")
    """Methods to train (fourierf-vm, fourierf-cp, tensorf-vm, tensorf-cp, ...)."""
    scene_kind: Literal["auto", "blender", "llff", "nerfstudio", "colmap"] = "auto"
    """Which parser reads --data (auto: from the files it holds)."""
    views: int | None = None
    """Few-shot: train on this many views chosen by the parser."""
    view_ids: tuple[int, ...] | None = None
    """Explicit training view ids (overrides --views)."""
    test_every: int = 8
    """Blender: evaluate every k-th test view (8 gives 25 of lego's 200); LLFF holds out every 8th image itself."""
    parser_args: tuple[str, ...] = ()
    """More parser flags, passed as they are (e.g. --parser-args --near 2.5)."""
    train_args: tuple[str, ...] = ()
    """More fourierf-train flags for every run, passed as they are (e.g. --train-args --optimizer.lr-grids 0.08; a
    flag a method does not use changes nothing for it). They are not part of a run's key: keep them fixed on resume."""
    iters: tuple[int, ...] = (800,)
    """Iteration budgets to sweep."""
    eval_points: int = 10
    """Evaluate at every 1/N of the budget (plus 25% and 50% when N >= 4)."""
    downscale: tuple[int, ...] | None = None
    """Image downscale factors to sweep (default: the parser's own)."""
    grid_voxels: tuple[int, ...] = (128**3,)
    """Final grid sizes (voxel counts) to sweep."""
    init_voxels: int = 64**3
    """Initial grid size (voxel count) of every run."""
    step_ratio: tuple[float, ...] = (0.5,)
    """Ray-marching step in voxels (more samples per ray when smaller) to sweep."""
    batch_size: tuple[int, ...] = (1024,)
    """Rays per batch to sweep."""
    f0: tuple[float, ...] | None = None
    """Initial Fourier cutoffs to sweep (default: each method's own); ignored by methods without the curriculum."""
    ramp_fraction: tuple[float, ...] | None = None
    """Growth lengths (fraction of the run until the band is fully open) to sweep (default: each method's own)."""
    seeds: tuple[int, ...] = (20211202,)
    """Seeds to sweep."""
    delta_values: tuple[float, ...] = ()
    """The Δ ablation: ramp fractions for --delta-methods at --delta-iters, each evaluated at its end only."""
    delta_methods: tuple[str, ...] = ("fourierf-vm",)
    """Methods of the Δ ablation (they must have the Fourier curriculum)."""
    delta_iters: int | None = None
    """Budget of the Δ ablation runs (default: the first --iters)."""
    profile_phases: ProfileMode = "first"
    """Record the per-phase time breakdown for the first run of each method, every run, or none."""
    output_dir: Path = Path("outputs/bench")
    """A new timestamped folder is made under this one."""
    resume: Path | None = None
    """Continue (or extend) the bench in this folder: finished runs are skipped, new ones join the same CSV."""
    executor: Literal["local", "ray"] = "local"
    """Local process pool, or a Ray cluster (pip install 'fourierf[ray]')."""
    ray_address: str | None = None
    """Ray cluster address ('auto' joins the running cluster; default: start a local Ray instance)."""
    ray_gpus_per_run: float = 0.0
    """GPUs each run reserves on a Ray cluster."""
    workers: int = 1
    """Local runs at once (timings are cleanest with 1)."""
    threads: int | None = None
    """Torch threads per run (default: cores / workers locally, 1 per Ray task)."""
    device: Literal["auto", "cpu", "cuda"] = "auto"
    lpips_weights: Path | None = None
    """LPIPS-alex v0.1 weights (default: $FOURIERF_LPIPS_WEIGHTS or ../shared/lpips; without them LPIPS is skipped)."""
    keep_checkpoints: bool = False
    """Keep every evaluated checkpoint (default: only the final one is kept)."""
    title: str | None = None
    """Report title (default: from the scene and views)."""
    dry_run: bool = False
    """Print the planned runs and exit."""


def detect_scene(cfg: BenchConfig) -> Scene:
    """The scene, its parser and the parser flags; a missing or unreadable folder is a UserError."""
    data = cfg.data.expanduser().resolve()
    if not data.is_dir():
        fail(f"--data {cfg.data} is not a folder", "pass the scene folder (e.g. --data demo/lego_tiny)")
    markers: dict[SceneKind, tuple[str, ...]] = {
        "blender": ("transforms_train.json",),
        "llff": ("poses_bounds.npy",),
        "nerfstudio": ("transforms.json",),
        "colmap": ("colmap/sparse/0", "sparse/0", "sparse"),
    }
    present = [k for k, names in markers.items() if any((data / name).exists() for name in names)]
    kind = cfg.scene_kind if cfg.scene_kind != "auto" else (present[0] if present else None)
    if kind is None:
        fail(
            f"--data {cfg.data} holds none of transforms_train.json, poses_bounds.npy, transforms.json or a COLMAP "
            "model (sparse/0)",
            "pass a scene folder (fourierf-process-data makes one from a folder of photos)",
        )
    if kind not in present:
        fail(f"--scene-kind {kind} needs {' or '.join(markers[kind])} in {cfg.data}, which is missing", "check --data")
    if cfg.test_every < 1:
        fail(f"--test-every {cfg.test_every} is not valid", "pass 1 (every test view) or more")
    args: list[str] = []
    if cfg.view_ids is not None:
        args += ["--view-ids", *map(str, cfg.view_ids)]
    elif cfg.views is not None:
        args += ["--num-views", str(cfg.views)]
    if kind == "blender":
        args += ["--test-every", str(cfg.test_every)]
    return Scene(data, kind, tuple(args) + tuple(cfg.parser_args))


def plan_runs(cfg: BenchConfig) -> list[RunSpec]:
    """The main sweep, then the Δ ablation (a run in both is trained once), with the profiled runs marked."""
    common = {
        "downscale": cfg.downscale if cfg.downscale is not None else (None,),
        "grid_voxels": cfg.grid_voxels,
        "init_voxels": cfg.init_voxels,
        "step_ratio": cfg.step_ratio,
        "batch_size": cfg.batch_size,
        "seeds": cfg.seeds,
    }
    main = SweepSpec(
        methods=cfg.methods,
        iters=cfg.iters,
        f0=cfg.f0 if cfg.f0 is not None else (None,),
        ramp_fraction=cfg.ramp_fraction if cfg.ramp_fraction is not None else (None,),
        eval_points=cfg.eval_points,
        **common,
    )
    runs = expand(main)
    if cfg.delta_values:
        unknown = [m for m in cfg.delta_methods if m not in known_methods()]
        if unknown:
            fail(
                f"unknown method(s) {', '.join(unknown)} in --delta-methods",
                f"choose from: {', '.join(known_methods())}",
            )
        plain = [m for m in cfg.delta_methods if fourier_defaults(m) is None]
        if plain:
            fail(f"--delta-methods {', '.join(plain)} have no Fourier curriculum to ablate", "pass e.g. fourierf-vm")
        delta = SweepSpec(
            methods=cfg.delta_methods,
            iters=(cfg.delta_iters or cfg.iters[0],),
            f0=(cfg.f0[0],) if cfg.f0 else (None,),
            ramp_fraction=cfg.delta_values,
            eval_points=1,
            **{k: (v[:1] if isinstance(v, tuple) else v) for k, v in common.items()},
        )
        runs = merge_runs(runs + expand(delta))
    return designate_profiled(runs, cfg.profile_phases)


def describe_plan(runs: list[RunSpec]) -> list[str]:
    lines = [f"{len(runs)} runs:"]
    for r in runs:
        extra = " (phase profile)" if r.profile_phases else ""
        lines.append(f"  {r.key}: eval at steps {list(r.eval_steps())}, checkpoint every {r.steps_per_save()}{extra}")
    return lines


def make_executor(cfg: BenchConfig) -> tuple[LocalExecutor | RayExecutor, int]:
    if cfg.executor == "ray":
        threads = cfg.threads or 1
        return RayExecutor(cfg.ray_address, cpus_per_run=threads, gpus_per_run=cfg.ray_gpus_per_run), threads
    if cfg.ray_address is not None:
        fail("--ray-address only applies to --executor ray", "add --executor ray or drop --ray-address")
    return LocalExecutor(cfg.workers), threads_per_worker(cfg.workers, cfg.threads)


def default_title(cfg: BenchConfig, scene: Scene) -> str:
    views = f"views {list(cfg.view_ids)}" if cfg.view_ids else f"{cfg.views} views" if cfg.views else "all views"
    return f"Accuracy vs time: {scene.data.name} ({views})"


def main(args: list[str] | None = None) -> coordinator.Outcome:
    argv = strip_verbose(sys.argv[1:] if args is None else args)
    cfg = tyro.cli(BenchConfig, args=argv)
    command = "fourierf-bench " + shlex.join(argv)
    outcome = run_bench(cfg, command)
    if outcome.failed:
        again = command if cfg.resume else f"{command} --resume {outcome.out_dir}"
        get_console().print(f"resume with: {again}", soft_wrap=True)
        raise SystemExit(1)
    return outcome


def run_bench(cfg: BenchConfig, command: str, preamble: list[str] | None = None) -> coordinator.Outcome:
    """Plan, run what is not done yet, and write the report; failed runs are listed in the outcome, not raised."""
    console = get_console()
    scene = detect_scene(cfg)
    runs = plan_runs(cfg)
    if cfg.dry_run:
        for line in describe_plan(runs):
            console.print(line, soft_wrap=True)
        return coordinator.Outcome(Path("."))
    lpips = cfg.lpips_weights or default_lpips_weights()
    if cfg.lpips_weights is not None and not cfg.lpips_weights.is_file():
        fail(f"--lpips-weights {cfg.lpips_weights} does not exist", "pass the LPIPS-alex v0.1 .pth file")
    if lpips is None:
        warn("LPIPS weights not found; LPIPS is left out of the report (pass --lpips-weights PATH)")
    executor, threads = make_executor(cfg)
    out_dir = coordinator.resume_dir(cfg.resume) if cfg.resume else coordinator.claim_output_dir(cfg.output_dir)
    out_dir = out_dir.resolve()
    tasks = [
        RunTask(r, scene, out_dir, threads, cfg.device, lpips, cfg.keep_checkpoints, tuple(cfg.train_args))
        for r in runs
    ]  # fmt: skip
    settings = asdict(cfg) | {"command": command, "threads_per_run": threads}
    coordinator.write_plan(out_dir, tasks, settings)
    todo = coordinator.still_to_run(tasks, out_dir)
    console.print(f"bench folder {out_dir}: {len(todo)} of {len(tasks)} runs to do", soft_wrap=True)

    def progress(result: RunResult, i: int, n: int) -> None:
        if result.ok:
            final = result.rows[-1]
            console.print(
                f"[{i}/{n}] {result.key}: PSNR {final['psnr']:.2f} at step {final['step']}, "
                f"trained in {format_duration(result.record.get('train_seconds') or float('nan'))}",
                soft_wrap=True,
            )
        else:
            console.print(f"[{i}/{n}] [red]{result.key} failed[/red]: {result.error}", soft_wrap=True)

    outcome = coordinator.run_tasks(todo, executor, out_dir, progress)
    title = cfg.title or default_title(cfg, scene)
    outcome.markdown, outcome.plots = coordinator.build_report(out_dir, title, preamble or [f"Command: `{command}`."])
    console.print(f"report: {out_dir / coordinator.REPORT}", soft_wrap=True)
    for key, why in outcome.failed.items():
        console.print(f"[red]failed[/red] {key}: {why}", soft_wrap=True)
    return outcome


def entrypoint() -> None:
    run_cli(main)


if __name__ == "__main__":
    entrypoint()
