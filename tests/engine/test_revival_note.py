"""The trainer's last lines say where a dead density field was revived, so a user (and the benchmark harness) can
tell a run revival acted on from one it did not; a run without revivals says nothing of them."""

from __future__ import annotations

from pathlib import Path

import pytest

from fourierf_plugin.pipelines.base import Pipeline
from tests.helpers import train_tiny

NOTE = "a dead density field was revived on"


@pytest.mark.parametrize("count", [0.0, 3.0])
def test_the_end_of_training_names_the_revived_batches(tmp_path: Path, monkeypatch, capsys, count: float) -> None:
    plain = Pipeline.read_metrics

    def with_count(metrics):  # the tiny scene's softplus density cannot revive: the count is given
        return plain(metrics) | {"revived_batches": count}

    monkeypatch.setattr(Pipeline, "read_metrics", staticmethod(with_count))
    train_tiny(tmp_path, iters=4)
    out = capsys.readouterr().out
    assert (f"{NOTE} 3 training batches" in out) if count else (NOTE not in out)
