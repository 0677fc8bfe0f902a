"""Checkpoint files: round trip, pruning, atomic failure handling and refusal of unreadable/unsafe files."""

from __future__ import annotations

import errno
import io
import os
from pathlib import Path

import pytest
import torch

from fourierf_plugin.engine import checkpoint as ckpt
from fourierf_plugin.engine.checkpoint import (
    CHECKPOINT_GLOB,
    list_checkpoints,
    load_checkpoint,
    load_latest_checkpoint,
    save_checkpoint,
)
from fourierf_plugin.utils.errors import UserError


def _state(step: int) -> dict:
    gen = torch.Generator().manual_seed(step)
    return {
        "step": step,
        "model": {
            "density_plane.0": torch.randn(1, 4, 8, 8, generator=gen),
            "basis.weight": torch.randn(3, 5, generator=gen),
        },
        "optimizer": {"lr": 0.02, "betas": [0.9, 0.99]},
        "scene": "lego",
        "cutoff": 0.25,
    }


def _no_temp_files(directory: Path) -> bool:
    return not [p for p in directory.iterdir() if ".tmp" in p.name]


def test_round_trip_keeps_tensors_and_plain_values(tmp_path: Path) -> None:
    state = _state(123)
    path = save_checkpoint(state, tmp_path / "checkpoints", step=123)
    assert path.name == "step-000000123.ckpt"
    assert path.match(CHECKPOINT_GLOB)
    loaded = load_checkpoint(path)
    assert loaded["step"] == 123 and loaded["scene"] == "lego" and loaded["cutoff"] == 0.25
    assert loaded["optimizer"] == {"lr": 0.02, "betas": [0.9, 0.99]}
    for key, tensor in state["model"].items():
        assert torch.equal(loaded["model"][key], tensor)
        assert loaded["model"][key].device.type == "cpu"
    assert _no_temp_files(path.parent)


def test_keep_last_prunes_oldest_and_list_is_sorted_by_step(tmp_path: Path) -> None:
    for step in (5, 100, 20, 1000, 7):
        save_checkpoint(_state(step), tmp_path, step=step, keep_last=3)
    # 7 was written last: it survives even though it is not among the three highest steps.
    assert [p.name for p in list_checkpoints(tmp_path)] == [
        "step-000000007.ckpt",
        "step-000000100.ckpt",
        "step-000001000.ckpt",
    ]
    assert [load_checkpoint(p)["step"] for p in list_checkpoints(tmp_path)] == [7, 100, 1000]


def test_keep_last_zero_keeps_everything(tmp_path: Path) -> None:
    for step in range(5):
        save_checkpoint(_state(step), tmp_path, step=step, keep_last=0)
    assert len(list_checkpoints(tmp_path)) == 5


def test_list_ignores_temp_files_and_other_names(tmp_path: Path) -> None:
    save_checkpoint(_state(1), tmp_path, step=1)
    for name in (".step-000000002.ckpt.tmp-999", "step-abc.ckpt", "notes.txt", "step-000000003.ckpt.bak"):
        (tmp_path / name).write_bytes(b"junk")
    (tmp_path / "step-000000004.ckpt").mkdir()
    assert [p.name for p in list_checkpoints(tmp_path)] == ["step-000000001.ckpt"]
    assert list_checkpoints(tmp_path / "missing") == []


def _fail_mid_write(monkeypatch: pytest.MonkeyPatch, written: list[Path]) -> None:
    def partial_save(obj: object, f: object, *args: object, **kwargs: object) -> None:
        if hasattr(f, "write"):
            f.write(b"PK\x03\x04 partial zip data")  # type: ignore[attr-defined]
            f.flush()  # type: ignore[attr-defined]
            written.append(Path(f.name))  # type: ignore[attr-defined]
        else:
            Path(f).write_bytes(b"PK\x03\x04 partial zip data")  # type: ignore[arg-type]
            written.append(Path(f))  # type: ignore[arg-type]
        raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))

    monkeypatch.setattr(ckpt.torch, "save", partial_save)


def test_disk_full_mid_save_keeps_previous_checkpoint(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    good = save_checkpoint(_state(10), tmp_path, step=10)
    good_bytes = good.read_bytes()
    written: list[Path] = []
    _fail_mid_write(monkeypatch, written)
    with pytest.raises(UserError) as info:
        save_checkpoint(_state(20), tmp_path, step=20)
    assert written and written[0].parent == tmp_path, "the temp file must live in the checkpoint directory"
    assert info.value.problem.startswith(f"disk full at {tmp_path}")
    assert f"the earlier checkpoint {good.name} is intact" in info.value.problem
    assert "free space" in (info.value.fix or "") and f"--load-dir {tmp_path.parent}" in (info.value.fix or "")
    monkeypatch.undo()
    assert _no_temp_files(tmp_path)
    assert list_checkpoints(tmp_path) == [good]
    assert good.read_bytes() == good_bytes
    assert load_checkpoint(good)["step"] == 10


class _FillingDisk(io.RawIOBase):
    """A real file whose writes fail with ENOSPC past ``limit`` bytes, like a disk filling up."""

    def __init__(self, path: Path, limit: int) -> None:
        self._raw = io.FileIO(path, "wb")
        self._limit = limit
        self._written = 0
        self.name = str(path)

    def writable(self) -> bool:
        return True

    def write(self, data: bytes) -> int:  # type: ignore[override]
        if self._written + len(data) > self._limit:
            raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))
        self._written += len(data)
        return self._raw.write(data)  # type: ignore[return-value]

    def fileno(self) -> int:
        return self._raw.fileno()

    def close(self) -> None:
        self._raw.close()
        super().close()


def test_real_torch_save_on_full_disk_is_a_user_error(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """The real torch.save turns the failed write into a RuntimeError; it must still become a UserError."""
    good = save_checkpoint(_state(1), tmp_path, step=1)
    real_open = open

    def opener(file: object, mode: str = "r", *args: object, **kwargs: object) -> object:
        if "w" in mode and ".tmp-" in str(file):
            return io.BufferedWriter(_FillingDisk(Path(str(file)), limit=600))  # what open() builds
        return real_open(file, mode, *args, **kwargs)  # type: ignore[call-overload]

    monkeypatch.setattr(ckpt, "open", opener, raising=False)
    with pytest.raises(UserError, match="disk full at"):
        save_checkpoint(_state(2), tmp_path, step=2)
    monkeypatch.undo()
    assert _no_temp_files(tmp_path)
    assert list_checkpoints(tmp_path) == [good]
    assert load_checkpoint(good)["step"] == 1


def test_runtime_error_wrapping_an_io_error_is_a_user_error(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    def torch_like_save(obj: object, f: object, *args: object, **kwargs: object) -> None:
        try:
            raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))
        except OSError:
            raise RuntimeError("[enforce fail at inline_container.cc] unexpected pos") from None

    monkeypatch.setattr(ckpt.torch, "save", torch_like_save)
    with pytest.raises(UserError, match="disk full at"):
        save_checkpoint(_state(1), tmp_path, step=1)
    assert _no_temp_files(tmp_path)


def test_programming_errors_are_not_disguised(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """A bug (not the user's disk) keeps its own exception type, and still leaves no temp file."""

    def broken_save(obj: object, f: object, *args: object, **kwargs: object) -> None:
        raise TypeError("cannot pickle 'generator' object")

    monkeypatch.setattr(ckpt.torch, "save", broken_save)
    with pytest.raises(TypeError):
        save_checkpoint(_state(1), tmp_path, step=1)
    assert _no_temp_files(tmp_path) and list_checkpoints(tmp_path) == []


def test_read_only_directory_is_a_user_error(tmp_path: Path) -> None:
    directory = tmp_path / "ro"
    good = save_checkpoint(_state(1), directory, step=1)
    directory.chmod(0o500)
    try:
        if os.access(directory, os.W_OK):
            pytest.skip("chmod does not stop writes here (running as root)")
        with pytest.raises(UserError) as info:
            save_checkpoint(_state(2), directory, step=2)
        assert str(directory) in info.value.problem and "--output-dir" in (info.value.fix or "")
    finally:
        directory.chmod(0o700)
    assert list_checkpoints(directory) == [good]
    assert _no_temp_files(directory)


def test_permission_denied_on_replace_is_a_user_error(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """Same as the read-only test but works as root: the final rename is refused."""
    good = save_checkpoint(_state(1), tmp_path, step=1)

    def deny(src: object, dst: object) -> None:
        raise PermissionError(errno.EACCES, os.strerror(errno.EACCES), str(dst))

    monkeypatch.setattr(ckpt.os, "replace", deny)
    with pytest.raises(UserError, match="Permission denied"):
        save_checkpoint(_state(2), tmp_path, step=2)
    monkeypatch.undo()
    assert list_checkpoints(tmp_path) == [good]
    assert _no_temp_files(tmp_path)


def test_checkpoint_directory_that_is_a_file_is_a_user_error(tmp_path: Path) -> None:
    blocker = tmp_path / "checkpoints"
    blocker.write_text("not a directory")
    with pytest.raises(UserError, match="checkpoints"):
        save_checkpoint(_state(1), blocker, step=1)


def test_truncated_checkpoint_is_a_user_error_naming_the_file(tmp_path: Path) -> None:
    path = save_checkpoint(_state(50), tmp_path, step=50)
    data = path.read_bytes()
    path.write_bytes(data[: len(data) // 2])
    with pytest.raises(UserError) as info:
        load_checkpoint(path)
    assert str(path) in info.value.problem and "unreadable" in info.value.problem
    assert "delete" in (info.value.fix or "")


@pytest.mark.parametrize("content", [b"", b"hello, not a checkpoint", bytes(range(256)) * 4])
def test_garbage_files_are_user_errors(tmp_path: Path, content: bytes) -> None:
    path = tmp_path / "step-000000001.ckpt"
    path.write_bytes(content)
    with pytest.raises(UserError, match="unreadable"):
        load_checkpoint(path)


def test_missing_checkpoint_is_a_user_error(tmp_path: Path) -> None:
    with pytest.raises(UserError, match="does not exist"):
        load_checkpoint(tmp_path / "step-000000001.ckpt")
    with pytest.raises(UserError, match="not a file"):
        load_checkpoint(tmp_path)


@pytest.mark.parametrize("obj", [[1, 2, 3], {"model": {}}, {"step": "12"}, {"step": True}, torch.zeros(3)])
def test_wrong_structure_is_a_user_error(tmp_path: Path, obj: object) -> None:
    path = tmp_path / "step-000000001.ckpt"
    torch.save(obj, path)
    with pytest.raises(UserError, match="not a fourierf checkpoint"):
        load_checkpoint(path)


class Payload:
    """An arbitrary object: unpickling it would mean running code chosen by whoever made the file."""

    def __init__(self) -> None:
        self.value = 42


def test_arbitrary_python_objects_are_refused(tmp_path: Path) -> None:
    path = tmp_path / "step-000000001.ckpt"
    torch.save({"step": 1, "payload": Payload()}, path)
    with pytest.raises(UserError) as info:
        load_checkpoint(path)
    assert str(path) in info.value.problem
    assert len(info.value.problem) < 600, "torch's multi-paragraph message should be shortened"


def test_latest_falls_back_past_a_truncated_newest(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    save_checkpoint(_state(100), tmp_path, step=100)
    newest = save_checkpoint(_state(200), tmp_path, step=200)
    newest.write_bytes(newest.read_bytes()[:100])
    path, state = load_latest_checkpoint(tmp_path)
    assert path.name == "step-000000100.ckpt" and state["step"] == 100
    assert torch.equal(state["model"]["basis.weight"], _state(100)["model"]["basis.weight"])
    assert "step-000000200.ckpt" in capsys.readouterr().err


def test_latest_picks_newest_and_accepts_a_run_directory(tmp_path: Path) -> None:
    for step in (1, 2, 3):
        save_checkpoint(_state(step), tmp_path / "run" / "checkpoints", step=step)
    assert load_latest_checkpoint(tmp_path / "run" / "checkpoints")[1]["step"] == 3
    assert load_latest_checkpoint(tmp_path / "run")[1]["step"] == 3


def test_latest_without_checkpoints_is_a_user_error(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(UserError) as info:
        load_latest_checkpoint(tmp_path)
    assert str(tmp_path) in info.value.problem and "train first" in (info.value.fix or "")
    with pytest.raises(UserError, match="does not exist"):
        load_latest_checkpoint(tmp_path / "nope")
    (tmp_path / "step-000000001.ckpt").write_bytes(b"garbage")
    with pytest.raises(UserError, match="none of the 1 checkpoints"):
        load_latest_checkpoint(tmp_path)
    assert "step-000000001.ckpt" in capsys.readouterr().err
