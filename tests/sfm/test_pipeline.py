"""Structure-from-motion through pycolmap on photos of a textured scene whose true cameras are known."""

from __future__ import annotations

import io
import subprocess
import sys
from pathlib import Path

import imageio.v3 as iio
import numpy as np
import pytest
from rich.console import Console

from fourierf_plugin.data.colmap_model import capture_from_model, read_model
from fourierf_plugin.sfm.alignment import pose_errors
from fourierf_plugin.sfm.matching import EXHAUSTIVE_LIMIT, resolve_matching
from fourierf_plugin.sfm.pipeline import SfmOptions, run_sfm
from fourierf_plugin.sfm.progress import StageDisplay
from fourierf_plugin.utils.errors import UserError
from tests.conftest import require_module
from tests.helpers import REPO_ROOT
from tests.sfm.textured_scene import opengl, write_photos

require_module("pycolmap", "structure-from-motion needs pycolmap (pip install '.[colmap]')")


def _display() -> tuple[StageDisplay, io.StringIO]:
    out = io.StringIO()
    return StageDisplay(Console(file=out, width=200)), out


def test_matching_choice() -> None:
    assert resolve_matching("auto", 20, ordered=False) == "exhaustive"
    assert resolve_matching("auto", 20, ordered=True) == "sequential"
    assert resolve_matching("auto", EXHAUSTIVE_LIMIT + 1, ordered=False) == "sequential"
    assert resolve_matching("exhaustive", 500, ordered=True) == "exhaustive"


@pytest.mark.parametrize("matching", ["exhaustive", "sequential"])
def test_sfm_recovers_the_true_cameras(tmp_path: Path, matching: str) -> None:
    truth = opengl(write_photos(tmp_path / "photos", n=8))
    names = sorted(p.name for p in (tmp_path / "photos").iterdir())
    display, log = _display()
    outcome = run_sfm(tmp_path / "photos", names, tmp_path / "colmap", SfmOptions(matching=matching), display)
    assert outcome.registered == names and outcome.unregistered == []
    assert outcome.matching == matching
    assert 0 < outcome.mean_reprojection_error < 1.0
    assert outcome.model_dir == tmp_path / "colmap" / "sparse" / "0"
    assert (tmp_path / "colmap" / "database.db").is_file() and not (tmp_path / "colmap" / "models").exists()
    text = log.getvalue()
    assert "✓ extracting SIFT features of 8 photos" in text and "8 of 8 photos registered" in text

    capture = capture_from_model(read_model(outcome.model_dir), tmp_path / "photos")
    errors = pose_errors(np.stack([f.camera_to_world for f in capture.frames]), truth)
    assert np.median(errors.rotation_deg) < 1.0
    assert np.median(errors.centre_error_percent) < 2.0
    intr = capture.frames[0].intrinsics
    assert intr.camera_model == "OPENCV" and intr.fx == pytest.approx(130.0, rel=0.03)


def test_photos_that_share_nothing_are_a_clear_error(tmp_path: Path) -> None:
    rng = np.random.default_rng(0)
    folder = tmp_path / "noise"
    folder.mkdir()
    for i in range(4):  # independent noise: features, but no two photos of one scene
        iio.imwrite(folder / f"n{i}.png", rng.integers(0, 256, (96, 128, 3)).astype(np.uint8))
    names = sorted(p.name for p in folder.iterdir())
    with pytest.raises(UserError, match=r"(no two of the 4 photos|none of the 4 photos)") as info:
        run_sfm(folder, names, tmp_path / "colmap", SfmOptions(), _display()[0])
    assert "overlap" in info.value.fix


def test_compression_still_works_after_pycolmap_is_imported() -> None:
    """pycolmap carries zlib functions of its own: loaded before the system zlib, PNG writing aborts the process."""
    code = (
        "from fourierf_plugin.sfm.colmap_library import import_pycolmap; import_pycolmap(); "
        "import numpy as np, imageio.v3 as iio, tempfile, os; "
        "img = np.random.default_rng(0).integers(0, 256, (1080, 1920, 3)).astype(np.uint8); "
        "path = os.path.join(tempfile.mkdtemp(), 'x.png'); [iio.imwrite(path, img) for _ in range(3)]; print('ok')"
    )
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=REPO_ROOT, timeout=120)
    assert done.returncode == 0 and done.stdout.strip() == "ok", done.stderr[-2000:]
