"""Evaluating a run (``engine.evaluation``): an interrupted evaluation never leaves a half-filled render folder, and
never removes a folder it did not make."""

from __future__ import annotations

from pathlib import Path

import pytest

from fourierf_plugin.engine.evaluation import evaluate
from fourierf_plugin.engine.loading import LoadedRun, load_run
from fourierf_plugin.method_configs import config_registry
from fourierf_plugin.utils.errors import UserError
from tests.helpers import TINY_TEST_VIEWS, train_tiny


@pytest.fixture(scope="module")
def run(tmp_path_factory: pytest.TempPathFactory) -> LoadedRun:
    _, run_dir = train_tiny(tmp_path_factory.mktemp("run"), iters=6)
    return load_run(run_dir / "config.json", config_registry())


class Stop(Exception):
    pass


def test_an_interrupted_evaluation_leaves_no_render_folder_and_the_next_one_completes(
    run: LoadedRun, tmp_path: Path
) -> None:
    renders = tmp_path / "renders"
    scored: list[str] = []

    def stop_after_two(item: dict) -> None:
        scored.append(item["name"])
        if len(scored) == 2:
            raise Stop

    with pytest.raises(Stop):
        evaluate(run, "test", render_dir=renders, on_view=stop_after_two)
    assert not renders.exists(), "a render folder must only ever hold a complete set"
    assert not list(tmp_path.iterdir()), "the interrupted evaluation removes the partial folder it made"

    report = evaluate(run, "test", render_dir=renders)
    assert len(list(renders.glob("*.png"))) == TINY_TEST_VIEWS == report["num_views"]
    assert [p.name for p in tmp_path.iterdir()] == ["renders"]
    with pytest.raises(UserError, match="--overwrite"):
        evaluate(run, "test", render_dir=renders)  # an earlier set is kept unless the caller says to replace it
    again = evaluate(run, "test", render_dir=renders, overwrite=True)
    assert sorted(p.stem for p in renders.glob("*.png")) == sorted(item["name"] for item in again["per_image"])
    assert [p.name for p in tmp_path.iterdir()] == ["renders"]


def test_an_evaluation_never_removes_a_folder_it_did_not_make(run: LoadedRun, tmp_path: Path) -> None:
    """A folder beside the renders, named like a temporary one, is the user's: it stays."""
    theirs = tmp_path / "renders.partial"
    theirs.mkdir()
    (theirs / "notes.txt").write_text("keep")
    evaluate(run, "test", render_dir=tmp_path / "renders")
    assert (theirs / "notes.txt").read_text() == "keep"


def test_a_stopped_evaluation_removes_the_parent_folders_it_made_and_keeps_the_users(
    run: LoadedRun, tmp_path: Path
) -> None:
    (tmp_path / "mine").mkdir()

    def stop(item: dict) -> None:
        raise KeyboardInterrupt

    for render_dir in (tmp_path / "new" / "deeper" / "renders", tmp_path / "mine" / "renders"):
        with pytest.raises(KeyboardInterrupt):
            evaluate(run, "test", render_dir=render_dir, on_view=stop)
    assert [p.name for p in tmp_path.rglob("*")] == ["mine"], "an empty folder of the user's stays"
