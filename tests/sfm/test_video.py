"""Evenly spaced frames of a clip through imageio (a GIF here: it needs no ffmpeg plugin)."""

from __future__ import annotations

from pathlib import Path

import imageio.v3 as iio
import numpy as np
import pytest

from fourierf_plugin.sfm.video import count_frames, evenly_spaced, extract_frames
from fourierf_plugin.utils.errors import UserError


def _clip(path: Path, n: int) -> np.ndarray:
    """A GIF whose frame i is flat grey level 20 i (exact through GIF's palette)."""
    frames = np.stack([np.full((16, 20, 3), 20 * i, dtype=np.uint8) for i in range(n)])
    iio.imwrite(path, frames, duration=40, loop=0)
    return frames


@pytest.mark.parametrize(("total", "count"), [(10, 4), (7, 7), (100, 3), (5, 9), (9, 1)])
def test_evenly_spaced_spans_the_clip(total: int, count: int) -> None:
    picks = evenly_spaced(total, count)
    assert len(picks) == min(total, count)
    assert picks == sorted(set(picks)) and picks[0] >= 0 and picks[-1] <= total - 1
    if count > 1:
        assert picks[0] == 0 and picks[-1] == total - 1
        gaps = np.diff(picks)
        assert gaps.max() - gaps.min() <= 1


def test_frames_are_extracted_evenly_spaced(tmp_path: Path) -> None:
    _clip(tmp_path / "clip.gif", 10)
    assert count_frames(tmp_path / "clip.gif") == 10
    written = extract_frames(tmp_path / "clip.gif", tmp_path / "frames", 4)
    assert [p.name for p in written] == [f"frame_{i:05d}.png" for i in range(1, 5)]
    levels = [int(iio.imread(p)[0, 0, 0]) for p in written]
    assert levels == [20 * i for i in evenly_spaced(10, 4)] == [0, 60, 120, 180]


def test_a_short_clip_gives_all_its_frames_with_a_warning(tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    _clip(tmp_path / "clip.gif", 5)
    written = extract_frames(tmp_path / "clip.gif", tmp_path / "frames", 50)
    assert len(written) == 5
    assert "has only 5 frames" in capsys.readouterr().err


def test_unreadable_or_missing_videos_are_clear_errors(tmp_path: Path) -> None:
    (tmp_path / "broken.mp4").write_bytes(b"not a video" * 10)
    with pytest.raises(UserError, match=r"cannot read the video .*broken\.mp4") as info:
        extract_frames(tmp_path / "broken.mp4", tmp_path / "frames", 10)
    assert "pip install '.[video]'" in info.value.fix
    with pytest.raises(UserError, match="video not found"):
        extract_frames(tmp_path / "none.mp4", tmp_path / "frames", 10)
    _clip(tmp_path / "clip.gif", 5)
    with pytest.raises(UserError, match="--num-frames must be at least 3"):
        extract_frames(tmp_path / "clip.gif", tmp_path / "frames", 2)
