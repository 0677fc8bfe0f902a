"""``fourierf-eval`` never deletes or replaces what a user named: an existing report or render folder is refused
without ``--overwrite``, ``--render-dir ..`` is refused even with it, and renders appear only as a complete set."""

from __future__ import annotations

import json
import shutil
import signal
from pathlib import Path

import pytest

from fourierf_plugin.scripts import eval as eval_script
from fourierf_plugin.scripts.cli import EXIT_USER_ERROR
from fourierf_plugin.utils.interrupt import Interrupted
from tests.helpers import TINY_TEST_VIEWS, cli_exit_code, train_tiny


@pytest.fixture(scope="module")
def config(tmp_path_factory: pytest.TempPathFactory) -> Path:
    _, run_dir = train_tiny(tmp_path_factory.mktemp("run"), iters=6)
    return run_dir / "config.json"


def snapshot(folder: Path) -> dict[str, bytes]:
    return {str(p.relative_to(folder)): p.read_bytes() for p in sorted(folder.rglob("*")) if p.is_file()}


def test_a_render_dir_holding_user_files_is_refused_and_left_as_it_was(config: Path, tmp_path: Path) -> None:
    mine = tmp_path / "mine"
    mine.mkdir()
    (mine / "thesis.tex").write_text("years of work")
    (mine / "figure.png").write_bytes(b"not a render")
    before = snapshot(mine)
    for overwrite in ([], ["--overwrite"]):
        args = ["--load-config", str(config), "--output-path", str(tmp_path / "eval.json"), "--render-dir", str(mine)]
        assert cli_exit_code(eval_script.main, args + overwrite) == EXIT_USER_ERROR
        assert snapshot(mine) == before
    assert sorted(p.name for p in tmp_path.iterdir()) == ["mine"], "nothing else is made or left behind"


def test_render_dir_dot_dot_never_empties_the_parent(
    config: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    work = tmp_path / "work"
    work.mkdir()
    (tmp_path / "keep.txt").write_text("keep")
    monkeypatch.chdir(work)
    before = snapshot(tmp_path)
    for overwrite in ([], ["--overwrite"]):
        args = ["--load-config", str(config), "--output-path", "eval.json", "--render-dir", "..", *overwrite]
        assert cli_exit_code(eval_script.main, args) == EXIT_USER_ERROR
        assert snapshot(tmp_path) == before


def test_an_existing_report_is_kept_unless_overwrite(config: Path, tmp_path: Path) -> None:
    report = tmp_path / "eval.json"
    report.write_text('{"mine": 1}')
    args = ["--load-config", str(config), "--output-path", str(report), "--render-dir", "none"]
    assert cli_exit_code(eval_script.main, args) == EXIT_USER_ERROR
    assert json.loads(report.read_text()) == {"mine": 1}
    eval_script.main([*args, "--overwrite"])
    assert json.loads(report.read_text())["num_views"] == TINY_TEST_VIEWS


def test_an_output_path_that_is_a_folder_is_refused_before_any_work(
    config: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    args = ["--load-config", str(config), "--output-path", str(tmp_path), "--render-dir", "none"]
    assert cli_exit_code(eval_script.main, args) == EXIT_USER_ERROR
    err = capsys.readouterr()
    assert "is a folder" in err.err and "psnr" not in err.out


def test_renders_go_to_a_new_folder_and_overwrite_replaces_only_earlier_renders(config: Path, tmp_path: Path) -> None:
    renders = tmp_path / "renders"
    base = ["--load-config", str(config), "--render-dir", str(renders)]
    eval_script.main([*base, "--output-path", str(tmp_path / "a.json")])
    assert len(list(renders.glob("*.png"))) == TINY_TEST_VIEWS
    assert cli_exit_code(eval_script.main, [*base, "--output-path", str(tmp_path / "b.json")]) == EXIT_USER_ERROR
    eval_script.main([*base, "--output-path", str(tmp_path / "b.json"), "--overwrite"])
    assert len(list(renders.glob("*.png"))) == TINY_TEST_VIEWS
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a.json", "b.json", "renders"], "no temporary left"


def test_the_default_render_folder_of_an_earlier_evaluation_is_kept(config: Path, tmp_path: Path) -> None:
    first = eval_script.main(["--load-config", str(config), "--output-path", str(tmp_path / "a.json")])
    second = eval_script.main(["--load-config", str(config), "--output-path", str(tmp_path / "b.json")])
    assert Path(first["render_dir"]).is_dir() and Path(second["render_dir"]).is_dir()
    assert first["render_dir"] != second["render_dir"]
    assert Path(second["render_dir"]).name == Path(first["render_dir"]).name + "-1"


def every_path(root: Path) -> set[str]:
    return {str(p.relative_to(root)) for p in root.rglob("*")}


@pytest.mark.parametrize("where", ["default", "default --overwrite", "--render-dir"])
def test_a_first_evaluation_stopped_mid_render_leaves_no_folder_it_made(
    config: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch, where: str
) -> None:
    """A run never evaluated (no RUN/renders/), stopped after its first view: the folders it made for the report and
    the renders go, a user's empty folder stays, and the next evaluation takes the first render folder."""
    run = Path(shutil.copytree(config.parent, tmp_path / "run", ignore=shutil.ignore_patterns("renders")))
    (tmp_path / "mine").mkdir()
    args = ["--load-config", str(run / "config.json"), "--output-path", str(tmp_path / "new" / "deeper" / "eval.json")]
    args += {
        "default": [],
        "default --overwrite": ["--overwrite"],
        "--render-dir": ["--render-dir", str(tmp_path / "mine" / "new" / "renders")],
    }[where]
    before = every_path(tmp_path)

    def stop(item: dict) -> None:
        raise Interrupted(signal.SIGTERM)  # what the stop-signal handler raises mid-work

    monkeypatch.setattr(eval_script, "print_view", stop)
    with pytest.raises(KeyboardInterrupt):
        eval_script.main(args)
    assert every_path(tmp_path) == before
    monkeypatch.undo()
    report = eval_script.main(args)
    if where.startswith("default"):
        assert Path(report["render_dir"]) == run / "renders" / f"test-step{report['step']:06d}"
