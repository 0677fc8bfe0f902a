"""LPIPS-alex v0.1: the authors' reference distances, basic metric properties, and clean errors for bad weights."""

from __future__ import annotations

from pathlib import Path

import imageio.v3 as iio
import numpy as np
import pytest
import torch

from fourierf_plugin.utils.errors import UserError
from fourierf_plugin.utils.lpips import LPIPS, WEIGHTS_ENV, default_lpips_weights


def _weights(shared_dir: Path) -> Path:
    return shared_dir / "lpips" / "lpips_alex_v0.1.pth"


def _load_png(path: Path) -> torch.Tensor:
    arr = np.asarray(iio.imread(path))
    if arr.ndim == 2:
        arr = np.stack([arr] * 3, axis=-1)
    return torch.from_numpy(arr[..., :3].astype(np.float32) / 255.0)


@pytest.fixture
def model(shared_dir: Path) -> LPIPS:
    return LPIPS(_weights(shared_dir))


def test_reference_distances(shared_dir: Path, model: LPIPS) -> None:
    ref, p0, p1 = (_load_png(shared_dir / "lpips" / f"ex_{n}.png") for n in ("ref", "p0", "p1"))
    assert model.distance(ref, p0) == pytest.approx(0.722, abs=1e-3)
    assert model.distance(ref, p1) == pytest.approx(0.138, abs=1e-3)


def test_identical_images_give_zero(model: LPIPS) -> None:
    img = torch.rand(48, 40, 3, generator=torch.Generator().manual_seed(0))
    assert model.distance(img, img.clone()) == pytest.approx(0.0, abs=1e-7)


def test_symmetric_and_positive(model: LPIPS) -> None:
    gen = torch.Generator().manual_seed(1)
    a = torch.rand(40, 48, 3, generator=gen)
    b = torch.rand(40, 48, 3, generator=gen)
    d_ab, d_ba = model.distance(a, b), model.distance(b, a)
    assert d_ab > 0.0
    assert d_ab == pytest.approx(d_ba, rel=1e-5, abs=1e-7)


def test_forward_batch_matches_distance(model: LPIPS) -> None:
    gen = torch.Generator().manual_seed(2)
    a = torch.rand(2, 3, 32, 32, generator=gen)
    b = torch.rand(2, 3, 32, 32, generator=gen)
    with torch.no_grad():
        out = model(a, b)
    assert out.shape == (2,)
    for i in range(2):
        assert float(out[i]) == pytest.approx(model.distance(a[i].permute(1, 2, 0), b[i].permute(1, 2, 0)), rel=1e-5)


def test_frozen_and_eval(model: LPIPS) -> None:
    assert not model.training
    assert all(not p.requires_grad for p in model.parameters())


def test_missing_weights_file_is_user_error(tmp_path: Path) -> None:
    path = tmp_path / "nope.pth"
    with pytest.raises(UserError) as info:
        LPIPS(path)
    assert str(path) in info.value.problem
    assert "--lpips-weights" in (info.value.fix or "")


def test_bad_state_dict_is_user_error(tmp_path: Path) -> None:
    path = tmp_path / "bad.pth"
    torch.save({"shift": torch.zeros(1, 3, 1, 1)}, path)
    with pytest.raises(UserError) as info:
        LPIPS(path)
    assert str(path) in info.value.problem
    assert "missing" in info.value.problem


def test_wrong_shape_state_dict_is_user_error(shared_dir: Path, tmp_path: Path) -> None:
    state = torch.load(_weights(shared_dir), map_location="cpu", weights_only=True)
    state["lins.0.weight"] = torch.zeros(1, 32, 1, 1)
    path = tmp_path / "wrong.pth"
    torch.save(state, path)
    with pytest.raises(UserError, match="wrong shape"):
        LPIPS(path)


def test_garbage_file_is_user_error(tmp_path: Path) -> None:
    path = tmp_path / "garbage.pth"
    path.write_bytes(b"not a checkpoint")
    with pytest.raises(UserError) as info:
        LPIPS(path)
    assert str(path) in info.value.problem


def test_default_weights_env_var(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    path = tmp_path / "w.pth"
    path.write_bytes(b"x")
    monkeypatch.setenv(WEIGHTS_ENV, str(path))
    assert default_lpips_weights() == path


def test_default_weights_falls_back_when_env_missing(monkeypatch: pytest.MonkeyPatch, tmp_path: Path) -> None:
    monkeypatch.setenv(WEIGHTS_ENV, str(tmp_path / "absent.pth"))
    found = default_lpips_weights()
    assert found is None or (found.is_file() and found.name == "lpips_alex_v0.1.pth")
