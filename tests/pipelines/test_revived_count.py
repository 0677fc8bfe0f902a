"""The training metrics carry the count of batches on which a dead ReLU density field was revived, so a run's log
says whether revival acted at all (a run it never acted on is TensoRF's ReLU to the bit); a field whose density
cannot revive (softplus, the synthetic preset) reports none."""

from __future__ import annotations

from pathlib import Path

import torch

from tests.helpers import TINY_SCENE
from tests.models.test_scene_effects import pipeline_for


def _fill_density(pipeline, line_value: float) -> None:
    """Density planes at 1 and lines at ``line_value``: every sample's raw density has that sign."""
    with torch.no_grad():
        for p in pipeline.model.field.density_grid.planes:
            p.fill_(1.0)
        for line in pipeline.model.field.density_grid.lines:
            line.fill_(line_value)


def test_a_softplus_field_reports_no_revival(tmp_path: Path) -> None:
    pipeline = pipeline_for(TINY_SCENE, tmp_path)
    _, metrics = pipeline.train_step(0)
    assert "revived_batches" not in metrics


def test_a_dead_relu_field_counts_each_revived_batch(llff_scene: Path, tmp_path: Path) -> None:
    pipeline = pipeline_for(llff_scene, tmp_path, "--pipeline.model.field.revive-patience", "1")
    _fill_density(pipeline, -0.5)  # every sample dark
    counts = []
    for step in range(2):
        _, metrics = pipeline.train_step(step)
        counts.append(pipeline.read_metrics(metrics)["revived_batches"])
    assert counts[0] >= 1 and counts[1] > counts[0]  # one or more density queries a step, each revived
    state = pipeline.model.field.state_dict()
    assert state["density_relu.revived"].item() == counts[1]  # kept in checkpoints, so a resume adds on


def test_a_live_relu_field_counts_none(llff_scene: Path, tmp_path: Path) -> None:
    pipeline = pipeline_for(llff_scene, tmp_path, "--pipeline.model.field.revive-patience", "1")
    _fill_density(pipeline, 0.5)
    _, metrics = pipeline.train_step(0)
    assert pipeline.read_metrics(metrics)["revived_batches"] == 0
