"""Run directories: safe names, no collisions (even racing threads), always inside the output directory."""

from __future__ import annotations

import os
import re
import threading
from datetime import datetime
from pathlib import Path

import pytest
from hypothesis import given
from hypothesis import strategies as st

from fourierf_plugin.engine.run_dir import make_run_dir, sanitize_name, timestamp_now
from fourierf_plugin.utils.errors import UserError

SAFE = re.compile(r"^[A-Za-z0-9._-]{1,100}$")


@pytest.mark.parametrize(
    ("raw", "expected"),
    [
        ("lego", "lego"),
        ("fern_v2.1-final", "fern_v2.1-final"),
        ("../../etc", ".._.._etc"),
        ("a/b\\c", "a_b_c"),
        ("..", "__"),
        (".", "_"),
        ("", "_"),
        ("scène 1", "sc_ne_1"),
        ("x" * 300, "x" * 100),
    ],
)
def test_sanitize_examples(raw: str, expected: str) -> None:
    assert sanitize_name(raw) == expected


@given(st.text(max_size=300))
def test_sanitize_always_gives_one_safe_component(raw: str) -> None:
    name = sanitize_name(raw)
    assert SAFE.match(name)
    assert name not in (".", "..")
    assert "/" not in name and os.sep not in name


def test_timestamp_format() -> None:
    stamp = timestamp_now()
    assert re.fullmatch(r"\d{4}-\d{2}-\d{2}_\d{6}", stamp)
    assert abs((datetime.strptime(stamp, "%Y-%m-%d_%H%M%S") - datetime.now()).total_seconds()) < 5


def test_layout_and_same_timestamp_never_collides(tmp_path: Path) -> None:
    first = make_run_dir(tmp_path, "lego", "fourierf", timestamp="2024-01-02_030405")
    second = make_run_dir(tmp_path, "lego", "fourierf", timestamp="2024-01-02_030405")
    third = make_run_dir(tmp_path, "lego", "fourierf", timestamp="2024-01-02_030405")
    assert first == tmp_path / "lego" / "fourierf" / "2024-01-02_030405"
    assert second == first.with_name("2024-01-02_030405-1")
    assert third == first.with_name("2024-01-02_030405-2")
    assert all(p.is_dir() for p in (first, second, third))


def test_default_timestamp_is_now(tmp_path: Path) -> None:
    run = make_run_dir(tmp_path, "lego", "fourierf")
    assert re.fullmatch(r"\d{4}-\d{2}-\d{2}_\d{6}", run.name)


def test_existing_file_with_the_name_is_skipped(tmp_path: Path) -> None:
    parent = tmp_path / "s" / "m"
    parent.mkdir(parents=True)
    (parent / "t").write_text("a file, not a run")
    assert make_run_dir(tmp_path, "s", "m", timestamp="t") == parent / "t-1"


@pytest.mark.parametrize("scene", ["../../escape", "/etc/passwd", "..", "a/../../b", "C:\\Windows"])
def test_hostile_names_stay_inside_output_dir(tmp_path: Path, scene: str) -> None:
    out = tmp_path / "out"
    run = make_run_dir(out, scene, "../m", timestamp="../../t")
    assert run.resolve().is_relative_to(out.resolve())
    assert run.parent.parent.parent == out
    assert ".." not in run.relative_to(out).parts


def test_racing_threads_all_get_distinct_dirs(tmp_path: Path) -> None:
    n = 8
    barrier = threading.Barrier(n)
    results: list[Path] = []
    errors: list[BaseException] = []
    lock = threading.Lock()

    def worker() -> None:
        try:
            barrier.wait()
            run = make_run_dir(tmp_path, "lego", "fourierf", timestamp="2024-01-02_030405")
            with lock:
                results.append(run)
        except BaseException as err:
            with lock:
                errors.append(err)

    threads = [threading.Thread(target=worker) for _ in range(n)]
    for t in threads:
        t.start()
    for t in threads:
        t.join(timeout=30)
    assert not errors
    assert len(results) == n and len(set(results)) == n
    names = sorted(p.name for p in results)
    assert names == sorted(["2024-01-02_030405"] + [f"2024-01-02_030405-{i}" for i in range(1, n)])


def test_unwritable_output_dir_is_a_user_error(tmp_path: Path) -> None:
    blocker = tmp_path / "outputs"
    blocker.write_text("a file where the output directory should be")
    with pytest.raises(UserError) as info:
        make_run_dir(blocker, "lego", "fourierf", timestamp="t")
    assert str(blocker) in info.value.problem and "--output-dir" in (info.value.fix or "")
