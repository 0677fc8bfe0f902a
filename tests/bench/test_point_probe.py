"""benchmarks/point_probe.py: which views see a point and what depth they render there, on a tiny trained run."""

from __future__ import annotations

from pathlib import Path

import pytest
import torch

from fourierf_plugin.scripts.cli import EXIT_USER_ERROR
from tests.helpers import cli_exit_code, load_benchmark, train_tiny


def test_a_rendered_surface_point_is_seen_at_its_own_depth(tmp_path: Path) -> None:
    point_probe = load_benchmark("point_probe")
    trainer, _ = train_tiny(tmp_path, iters=20)
    pipeline, step = trainer.pipeline, 20
    view = next(iter(pipeline.datamanager.eval_views("train")))
    index = (view.height // 2) * view.width + view.width // 3
    origin, direction = view.rays.origins[index], view.rays.directions[index]
    depth = float(pipeline.model.render_rays(origin[None], direction[None], step)["depth"][0])
    point = origin + depth * direction  # where this view's ray meets what the run renders
    first = point_probe.probe(pipeline, step, point)[0]
    assert (first.row, first.col) == (view.height // 2, view.width // 3)
    assert first.miss == pytest.approx(0.0, abs=1e-5)
    assert first.point_depth == pytest.approx(depth, rel=1e-5)
    assert first.rendered_depth == pytest.approx(depth, rel=1e-4)
    beyond = point_probe.probe(pipeline, step, origin + (depth * 1.5) * direction)[0]  # behind the surface
    assert beyond.point_depth > beyond.rendered_depth
    assert torch.isfinite(torch.tensor([beyond.miss, beyond.point_depth, beyond.rendered_depth])).all()


def test_a_missing_run_is_one_message_naming_the_file(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    point_probe = load_benchmark("point_probe")
    missing = tmp_path / "nowhere" / "config.json"
    code = cli_exit_code(point_probe.main, ["--run", str(missing), "--point", "0", "0", "0"])
    err = " ".join(capsys.readouterr().err.split())
    assert code == EXIT_USER_ERROR
    assert str(missing) in err and "fix:" in err and "Traceback" not in err
