"""benchmarks/picture_grid.py: the views a grid shows, picked by name or as the split's first ones."""

from __future__ import annotations

from pathlib import Path

import pytest

from tests.helpers import load_benchmark, train_tiny


def test_views_are_picked_by_name_or_as_the_splits_first(tmp_path: Path) -> None:
    picture_grid = load_benchmark("picture_grid")
    trainer, run_dir = train_tiny(tmp_path, iters=5)
    names = [view.name for view in trainer.pipeline.datamanager.eval_views("test")]
    assert len(names) >= 2, "the tiny scene needs two test views for this test"
    config = run_dir / "config.json"
    first = picture_grid.columns(config, "test", 1)
    assert [c["name"] for c in first] == names[:1]
    picked = picture_grid.columns(config, "test", 1, [names[-1]])
    assert [c["name"] for c in picked] == [names[-1]], "a named view wins over the split's first"
    rgb, depth = picked[0]["rgb"], picked[0]["depth"]
    assert rgb.shape[:2] == depth.shape[:2] == picked[0]["target"].shape[:2]
    with pytest.raises(SystemExit, match=f"no view r_nowhere in its test split \\(it has \\['{names[0]}'"):
        picture_grid.columns(config, "test", 1, ["r_nowhere"])
