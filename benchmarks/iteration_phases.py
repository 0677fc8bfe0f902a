"""Time one training iteration phase by phase on a saved state, for a checkout of fourierf (before/after a change).

The phases are measured from outside, by wrapping the pipeline's public pieces, so the same harness runs on code
that has no phase markers of its own (an older commit passed as ``--code-dir``: one that reads the run's config
format, i.e. the redesign of issue 16 or later):

    data (next_batch) · prepare (model.prepare: Fourier filtering + dense tables) · density (field.density) ·
    appearance (field.rgb) · sampling+compositing (the rest of the model's forward) · losses ·
    backward (incl. the filter's backward) · optimizer

    python benchmarks/iteration_phases.py RUN_DIR --step 700 --iters 20 [--code-dir OLD_CHECKOUT] --out phases.json

The state is the run's latest checkpoint (grid shapes, occupancy grid, box), trained further for ``--iters``
iterations at ``--step`` (its cutoffs and loss weights) after 3 warm-up iterations. Prints and writes ms per phase.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from collections import defaultdict
from pathlib import Path


def _known_only(payload: dict, cls: type) -> dict:
    """``payload`` without keys that dataclass ``cls`` (and the dataclasses nested in it) does not know."""
    import dataclasses
    import typing

    hints = typing.get_type_hints(cls)
    out = {}
    for key, value in payload.items():
        if key.startswith("_"):
            out[key] = value
        elif key in hints:
            nested = hints[key]
            is_dataclass = isinstance(nested, type) and dataclasses.is_dataclass(nested)
            out[key] = _known_only(value, nested) if is_dataclass and isinstance(value, dict) else value
    return out


def _config_for(path: Path, trainer_config: type) -> Path:
    """The run's config.json without options this (older) checkout does not know (e.g. profile_phases)."""
    import tempfile

    payload = json.loads(path.read_text())
    payload["config"] = _known_only(payload["config"], trainer_config)
    out = Path(tempfile.mkdtemp()) / "config.json"
    out.write_text(json.dumps(payload))
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("run_dir", type=Path)
    ap.add_argument("--step", type=int, required=True, help="the step whose cutoffs and weights are used")
    ap.add_argument("--iters", type=int, default=20)
    ap.add_argument("--code-dir", type=Path, default=None, help="import fourierf_plugin from this checkout")
    ap.add_argument("--threads", type=int, default=None)
    ap.add_argument("--out", type=Path, default=None)
    args = ap.parse_args()
    if args.code_dir is not None:
        sys.path.insert(0, str(args.code_dir.resolve()))
    import torch

    from fourierf_plugin.accel.allocator import keep_freed_memory
    from fourierf_plugin.configs.base import load_config
    from fourierf_plugin.engine.checkpoint import load_latest_checkpoint
    from fourierf_plugin.engine.machine import seed_everything
    from fourierf_plugin.engine.optimizers import build_optimizer
    from fourierf_plugin.engine.trainer import TrainerConfig
    from fourierf_plugin.method_configs import config_registry

    if args.threads:
        torch.set_num_threads(args.threads)
    keep_freed_memory()  # what the console scripts do at start-up
    config = load_config(_config_for(args.run_dir / "config.json", TrainerConfig), TrainerConfig, config_registry())
    pipeline = config.pipeline.setup(
        device=torch.device("cpu"), max_iters=config.max_num_iterations, generator=seed_everything(config.seed)
    )
    _, state = load_latest_checkpoint(args.run_dir / "checkpoints")
    pipeline.load_state_dict(state["pipeline"])
    model, field = pipeline.model, pipeline.model.field
    optimizer = build_optimizer(config.optimizer, model.param_groups())

    totals: defaultdict[str, float] = defaultdict(float)

    def timed(name: str, fn):
        def wrapper(*a, **k):
            start = time.perf_counter()
            try:
                return fn(*a, **k)
            finally:
                totals[name] += time.perf_counter() - start

        return wrapper

    pipeline.datamanager.next_batch = timed("data", pipeline.datamanager.next_batch)
    model.prepare = timed("prepare", model.prepare)
    field.density = timed("density", field.density)
    field.rgb = timed("appearance", field.rgb)
    model.loss_dict = timed("losses", model.loss_dict)
    forward = model.forward
    model.forward = timed("forward", forward)

    def iteration() -> None:
        loss, _ = pipeline.train_step(args.step)
        start = time.perf_counter()
        optimizer.zero_grad(set_to_none=True)
        loss.backward()
        middle = time.perf_counter()
        optimizer.step()
        totals["backward"] += middle - start
        totals["optimizer"] += time.perf_counter() - middle

    for _ in range(3):
        iteration()
    totals.clear()
    start = time.perf_counter()
    for _ in range(args.iters):
        iteration()
    wall = (time.perf_counter() - start) / args.iters
    ms = {k: v / args.iters * 1000 for k, v in totals.items()}
    ms["sampling+compositing"] = ms.pop("forward") - ms["density"] - ms["appearance"]
    ms["other"] = wall * 1000 - sum(ms.values())
    result = {
        "run_dir": str(args.run_dir),
        "step": args.step,
        "iters": args.iters,
        "cutoffs": list(model.cutoffs(args.step)),
        "resolution": field.resolution,
        "threads": torch.get_num_threads(),
        "code_dir": str(args.code_dir) if args.code_dir else None,
        "seconds_per_iteration": wall,
        "ms": ms,
    }
    print(json.dumps(result, indent=2))
    if args.out:
        args.out.write_text(json.dumps(result, indent=2) + "\n")


if __name__ == "__main__":
    main()
