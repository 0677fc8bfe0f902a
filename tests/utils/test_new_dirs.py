"""``NewDirs``: the folders a command made are removed when it stops, only if empty, and a folder that was there
before is never touched."""

from __future__ import annotations

from pathlib import Path

import pytest

from fourierf_plugin.utils.errors import UserError
from fourierf_plugin.utils.new_dirs import NewDirs


def test_a_stop_removes_only_the_empty_folders_this_call_made(tmp_path: Path) -> None:
    (tmp_path / "mine").mkdir()
    with pytest.raises(KeyboardInterrupt), NewDirs() as made:
        made.make(tmp_path / "mine" / "a" / "b", "--output-dir")
        made.make(tmp_path / "kept" / "c", "--output-dir")
        (tmp_path / "kept" / "work.png").write_bytes(b"finished")
        claimed = tmp_path / "claimed"
        claimed.mkdir()
        made.adopt(claimed)
        assert made.made[:2] == [tmp_path / "mine" / "a", tmp_path / "mine" / "a" / "b"], "not mine: it was there"
        raise KeyboardInterrupt
    assert sorted(str(p.relative_to(tmp_path)) for p in tmp_path.rglob("*")) == ["kept", "kept/work.png", "mine"]


def test_a_finished_block_keeps_every_folder(tmp_path: Path) -> None:
    with NewDirs() as made:
        made.make(tmp_path / "a" / "b", "--output-dir")
    assert (tmp_path / "a" / "b").is_dir()


def test_a_file_in_the_way_is_one_clear_error_naming_the_flag(tmp_path: Path) -> None:
    (tmp_path / "file.txt").write_text("mine")
    with pytest.raises(UserError, match=r"cannot write to .*file\.txt.*not a folder") as info, NewDirs() as made:
        made.make(tmp_path / "file.txt" / "out", "--output-dir")
    assert info.value.fix is not None and "--output-dir" in info.value.fix
    assert (tmp_path / "file.txt").read_text() == "mine"
