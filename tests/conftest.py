"""Shared fixtures: the ../shared material (skipped outside CI when absent, a failure in CI) and the torch threads."""

from __future__ import annotations

import importlib
import os
from collections.abc import Iterator
from pathlib import Path
from types import ModuleType
from typing import NoReturn

import pytest
import torch

from tests.helpers import TINY_SCENE
from tests.scenes import write_llff_scene

REPO_ROOT = Path(__file__).resolve().parents[1]
SHARED_DIR = Path(os.environ.get("FOURIERF_SHARED", REPO_ROOT.parent / "shared"))


def require_shared(*parts: str) -> Path:
    """Path under ../shared; skips with the reason when it is absent, but fails in CI where it must be present."""
    path = SHARED_DIR.joinpath(*parts)
    if not path.exists():
        skip_outside_ci(f"{path} is absent: clone the project with its shared/ material beside it to run this test")
    return path


def skip_outside_ci(reason: str) -> NoReturn:
    """Skip a test whose requirement is missing here, but fail it in CI, which must provide every requirement."""
    if os.environ.get("CI", "").lower() == "true":
        pytest.fail(f"CI=true but {reason}")
    pytest.skip(reason)


def require_module(name: str, why: str) -> ModuleType:
    """An optional package (an extra); skips with ``why`` when it is not installed, but fails in CI, which installs
    every extra the tests use (the dev extra)."""
    try:
        return importlib.import_module(name)
    except ImportError:
        skip_outside_ci(f"{name} is not installed: {why}")


@pytest.fixture
def pycolmap_installed() -> ModuleType:
    return require_module("pycolmap", "structure-from-motion needs pycolmap (pip install '.[colmap]')")


@pytest.fixture
def shared_dir() -> Path:
    return require_shared()


@pytest.fixture(scope="session", autouse=True)
def single_torch_thread() -> Iterator[None]:
    """One torch thread per test process, restored afterwards.

    Why: ``make test`` runs two pytest workers on a two-core machine; with torch's default threads each would
    oversubscribe the cores (a 5 s tiny run took 20 s), and tiny grids gain nothing from a second thread anyway.
    """
    before = torch.get_num_threads()
    torch.set_num_threads(1)
    yield
    torch.set_num_threads(before)


@pytest.fixture(scope="module")
def llff_scene(tmp_path_factory) -> Path:
    """A 20-image synthetic LLFF scene with 8x6 images (tests/scenes.py), one per test module."""
    return write_llff_scene(tmp_path_factory.mktemp("llff") / "scene")


@pytest.fixture(params=["blender", "llff"])
def either_scene(request: pytest.FixtureRequest, llff_scene: Path) -> Path:
    """Each kind of scene in turn: the bundled tiny Blender object (box rays) and the synthetic LLFF one (NDC rays)."""
    return TINY_SCENE if request.param == "blender" else llff_scene
