"""The product's tracked text files describe the product as it is: no session numbers (how a number came to be is
the git log's job). A short allow-list keeps the legitimate senses: an SSH session, pytest's session scope."""

from __future__ import annotations

import re
import subprocess
from collections.abc import Iterable
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
HISTORY = re.compile(r"session [0-9]|sessions [0-9]|session\'s|session [a-z]+ [0-9]|Session [0-9]+:", re.IGNORECASE)
"""A work session numbered or named as the owner of a rule: a number after it, or its possessive."""
ALLOWED = re.compile(r"ssh session|scope=\"session\"|scope='session'|http session|websocket session", re.IGNORECASE)
"""The legitimate senses, removed from a line before it is checked."""
BINARY = {".png", ".jpg", ".jpeg", ".gif", ".pdf", ".npz", ".npy", ".pt", ".pth", ".ckpt", ".ply", ".zip", ".gz"}


def offending_lines(name: str, lines: Iterable[str]) -> list[str]:
    """``name:line: text`` for each line that names a work session, outside the allow-list."""
    return [
        f"{name}:{number}: {line.strip()[:160]}"
        for number, line in enumerate(lines, start=1)
        if HISTORY.search(ALLOWED.sub("", line))
    ]


def tracked_text_files() -> list[Path]:
    try:
        done = subprocess.run(["git", "ls-files", "-z"], cwd=REPO, capture_output=True, check=True)
    except (OSError, subprocess.CalledProcessError):
        pytest.skip("not a git checkout (or no git): the tracked files cannot be listed")
    names = [name for name in done.stdout.decode().split("\0") if name]
    return [REPO / name for name in names if Path(name).suffix.lower() not in BINARY]


def test_no_tracked_text_file_names_a_work_session() -> None:
    found = []
    for path in tracked_text_files():
        try:
            text = path.read_text(encoding="utf-8")
        except (FileNotFoundError, UnicodeDecodeError):  # deleted in the working tree, or binary
            continue
        found += offending_lines(str(path.relative_to(REPO)), text.splitlines())
    assert not found, "history in tracked files (say what and why; the git log keeps when):\n" + "\n".join(found)


def test_the_check_finds_history_and_spares_the_legitimate_senses() -> None:
    word = "session"  # the offending lines are built here, so that this file passes its own check
    lines = [
        f"TV 6 ({word} 46's rule)",
        f"# {word.title()} 12: the levers left",
        f"measured in {word}s 36-39",
        f"the rule of {word} forty 2",
        f"Ctrl-C, or a closed SSH {word} 2 minutes in",
        '@pytest.fixture(scope="session")',
        "the viewer's websocket session",
    ]
    assert offending_lines("f.py", lines) == [f"f.py:{n}: {line}" for n, line in enumerate(lines[:4], start=1)]
