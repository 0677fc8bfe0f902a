"""benchmarks/ab_speed.py's report on made-up timings: medians per side and their ratios, each run listed, and a
missing record is one clear error (the A/B itself needs two trainings per pair: the benchmark, not the tests)."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path
from types import ModuleType

import harness
import pytest

from tests.helpers import load_benchmark

SCRIPT = Path(__file__).resolve().parents[2] / "benchmarks" / "ab_speed.py"


@pytest.fixture(scope="module")
def ab_speed() -> ModuleType:
    return load_benchmark("ab_speed")


def marks(marker: str) -> tuple[str, str]:
    """The markers a section is written between."""
    return harness.markers(marker, "ab_speed.py")


def _rows() -> list[dict]:
    def row(label: str, seed: int, wall: float, psnr: float) -> dict:
        side = label.split("-")[0]
        return {"label": label, "seed": seed, "side": side, "train_wall_s": wall, "final_s_per_it": wall / 1000,
                "render_s": 3.0, "psnr": psnr}  # fmt: skip

    return [row("old-0", 1, 80.0, 21.0), row("new-0", 1, 90.0, 21.5), row("new-1", 2, 70.0, 21.25),
            row("old-1", 2, 100.0, 22.0)]  # fmt: skip


META = {"old": "abc", "new": "working tree", "describe": "a test", "pairs": 2, "seeds": [1, 2], "command": "cmd"}


def test_the_summary_gives_medians_their_ratio_and_every_run(ab_speed: ModuleType) -> None:
    lines = ab_speed.summary(_rows(), {"old": [0.1, 0.3], "new": [0.1, 0.1]}, META)
    whole = next(line for line in lines if line.startswith("| whole training run"))
    assert whole == "| whole training run, s (80.0 / 100.0 · 90.0 / 70.0) | 90.0 | 80.0 | 0.89 |"
    in_process = next(line for line in lines if "in-process" in line)
    assert in_process.endswith("| 0.2000 | 0.1000 | 0.50 |")
    assert "- test PSNR new: 21.50 (seed 1), 21.25 (seed 2)" in lines
    assert lines[0] == "a test"  # what differs, not which commits: the revisions stay in meta.json
    flagged = ab_speed.summary(_rows(), {"old": [0.1], "new": [0.1]}, META | {"new_flags": ["--x", "1"]})
    assert flagged[0] == "a test (extra flags, new: `--x 1`)"


def test_the_report_rewrites_its_section_from_the_record(ab_speed: ModuleType, tmp_path: Path) -> None:
    (tmp_path / "results.jsonl").write_text("".join(json.dumps(r) + "\n" for r in _rows()))
    (tmp_path / "iterations.json").write_text(json.dumps({"old": [0.2], "new": [0.1]}))
    (tmp_path / "meta.json").write_text(json.dumps(META))
    markdown = tmp_path / "BENCHMARKS.md"
    begin, end = marks(ab_speed.SCENES["lego"]["marker"])
    markdown.write_text(f"# Benchmarks\n\n{begin}\nold text\n{end}\n\n## After\n")
    ab_speed.write_report(tmp_path, markdown)
    text = markdown.read_text()
    assert "old text" not in text and "| 90.0 | 80.0 | 0.89 |" in text and text.endswith("## After\n")


def test_a_report_without_a_recorded_ab_is_one_clear_error(tmp_path: Path) -> None:
    done = subprocess.run(
        [sys.executable, str(SCRIPT), "--report", "--work", str(tmp_path), "--markdown", str(tmp_path / "B.md")],
        capture_output=True,
        text=True,
    )
    assert done.returncode != 0 and "Traceback" not in done.stderr
    assert f"no A/B recorded in {tmp_path}" in done.stderr and "results.jsonl" in done.stderr
    assert not (tmp_path / "B.md").exists()


def test_meta_names_each_side_by_its_commit(ab_speed: ModuleType) -> None:
    """A side named "HEAD" or "working tree" in meta.json would name another version after the next commit."""
    head = subprocess.run(["git", "rev-parse", "--short", "HEAD"], cwd=SCRIPT.parents[1], check=True,
                          capture_output=True, text=True).stdout.strip()  # fmt: skip
    assert ab_speed.revision_label("HEAD") == f"HEAD ({head})"
    assert ab_speed.revision_label(head) == head
    assert ab_speed.revision_label(None).startswith(f"the working tree on {head}")


def test_each_scene_reports_into_its_own_section(ab_speed: ModuleType, tmp_path: Path) -> None:
    (tmp_path / "results.jsonl").write_text("".join(json.dumps(r) + "\n" for r in _rows()))
    (tmp_path / "iterations.json").write_text(json.dumps({"old": [0.2], "new": [0.1]}))
    (lego_title, lego), (fern_title, fern) = ab_speed.section_of("lego", False), ab_speed.section_of("fern", False)
    markdown = tmp_path / "BENCHMARKS.md"
    markdown.write_text(
        "\n".join([marks(lego)[0], "lego A/B", marks(lego)[1], marks(fern)[0], "fern A/B", marks(fern)[1], ""])
    )
    (tmp_path / "meta.json").write_text(json.dumps(META | {"scene": "fern"}))
    ab_speed.write_report(tmp_path, markdown)
    text = markdown.read_text()
    assert "lego A/B" in text and "fern A/B" not in text and fern_title in text
    (tmp_path / "meta.json").write_text(json.dumps(META))  # a record from before --scene: lego's
    ab_speed.write_report(tmp_path, markdown)
    text = markdown.read_text()
    assert "lego A/B" not in text and lego_title in text and fern_title in text
    assert marks(lego)[0].startswith("<!-- ab_speed:begin"), "the lego section keeps its markers"


def test_an_option_ab_reports_into_its_own_section(ab_speed: ModuleType, tmp_path: Path) -> None:
    """Timing an option's flags must not overwrite the A/B of the last change to a default."""
    (tmp_path / "results.jsonl").write_text("".join(json.dumps(r) + "\n" for r in _rows()))
    (tmp_path / "iterations.json").write_text(json.dumps({"old": [0.2], "new": [0.1]}))
    (tmp_path / "meta.json").write_text(json.dumps(META | {"old_flags": [], "new_flags": ["--x", "1"]}))
    lego, (option_title, option) = ab_speed.SCENES["lego"]["marker"], ab_speed.section_of("lego", True)
    markdown = tmp_path / "BENCHMARKS.md"
    markdown.write_text("\n".join([marks(lego)[0], "lego A/B", marks(lego)[1], ""]))
    ab_speed.write_report(tmp_path, markdown)
    text = markdown.read_text()
    assert "lego A/B" in text and option_title in text and "| 90.0 | 80.0 | 0.89 |" in text
    assert all(m in text for m in marks(option)) and option != lego


def test_unbalanced_side_flags_are_one_clear_error(tmp_path: Path) -> None:
    done = subprocess.run(
        [sys.executable, str(SCRIPT), "--new-flags", '--x "1', "--work", str(tmp_path / "w")],
        capture_output=True,
        text=True,
    )
    assert done.returncode == 2 and "Traceback" not in done.stderr
    assert "--old-flags / --new-flags" in done.stderr and not (tmp_path / "w").exists()
