"""The wheel installs the flat-layout folders under fourierf_plugin only, with every console script."""

from __future__ import annotations

import importlib
import importlib.util
import pkgutil
import re
import shutil
import subprocess
import sys
import zipfile
from collections.abc import Iterator
from pathlib import Path

import pytest

from tests.helpers import REPO_ROOT

REQUIRED = [
    "fourierf_plugin/data/parsers/blender.py",
    "fourierf_plugin/data/parsers/__init__.py",
    "fourierf_plugin/method_configs/presets.py",
    "fourierf_plugin/method_configs/__init__.py",
    "fourierf_plugin/method_configs/finalize.py",
    "fourierf_plugin/method_configs/scene_presets.py",
    "fourierf_plugin/field_components/fourier.py",
    "fourierf_plugin/accel/__init__.py",
    "fourierf_plugin/accel/ops.py",
    "fourierf_plugin/synthetic/__init__.py",
    "fourierf_plugin/scripts/train.py",
    "fourierf_plugin/scripts/eval.py",
]
MAPPED = ("fourierf_plugin.data.parsers", "fourierf_plugin.method_configs")
SOURCE_FOLDERS = {
    REPO_ROOT / "fourierf_plugin": "fourierf_plugin",
    REPO_ROOT / "data" / "parsers": "fourierf_plugin/data/parsers",
    REPO_ROOT / "method_configs": "fourierf_plugin/method_configs",
}
FORBIDDEN_PREFIXES = ("data/", "method_configs/", "tests/", "demo/", "benchmarks/", "tools/")
SCRIPTS = ("train", "eval", "export", "render", "synth", "process-data")  # fourierf-NAME


def _ignore_build_leftovers(directory: str, names: list[str]) -> set[str]:
    """Copy the source tree without the venv, VCS, caches, build output or datasets users keep in ./data."""
    skip = {".venv", ".git", "outputs", "build", "dist", "__pycache__", ".pytest_cache", ".ruff_cache", ".hypothesis"}
    ignored = {n for n in names if n in skip or n.endswith(".egg-info")}
    if Path(directory).resolve() == (REPO_ROOT / "data").resolve():
        ignored |= {n for n in names if n != "parsers"}
    return ignored


@pytest.fixture(scope="module")
def wheel(tmp_path_factory) -> Iterator[zipfile.ZipFile]:
    if importlib.util.find_spec("setuptools") is None:
        pytest.skip("setuptools is not importable in this environment (needed for --no-build-isolation)")
    # Build from a copy so the checkout gets no build/ or *.egg-info from the test.
    source = tmp_path_factory.mktemp("src") / "fourierf"
    shutil.copytree(REPO_ROOT, source, ignore=_ignore_build_leftovers)
    dist = tmp_path_factory.mktemp("dist")
    proc = subprocess.run(
        [sys.executable, "-m", "pip", "wheel", "--no-deps", "--no-build-isolation", "-q", "-w", str(dist), str(source)],
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert proc.returncode == 0, proc.stdout + proc.stderr
    (path,) = dist.glob("fourierf-*.whl")
    archive = zipfile.ZipFile(path)
    yield archive
    archive.close()


@pytest.mark.slow
def test_wheel_holds_the_mapped_packages(wheel: zipfile.ZipFile) -> None:
    names = set(wheel.namelist())
    for required in REQUIRED:
        assert required in names, required


@pytest.mark.slow
def test_wheel_installs_nothing_outside_the_package(wheel: zipfile.ZipFile) -> None:
    stray = [n for n in wheel.namelist() if n.startswith(FORBIDDEN_PREFIXES)]
    assert not stray, stray
    top = {n.split("/", 1)[0] for n in wheel.namelist()}
    assert {t for t in top if not t.endswith(".dist-info")} == {"fourierf_plugin"}


@pytest.mark.slow
def test_wheel_declares_every_console_script(wheel: zipfile.ZipFile) -> None:
    (entry_points,) = [n for n in wheel.namelist() if n.endswith(".dist-info/entry_points.txt")]
    text = wheel.read(entry_points).decode()
    assert "[console_scripts]" in text
    from fourierf_plugin import launch

    targets = dict(line.split(" = ") for line in text.splitlines() if line.startswith("fourierf-"))
    for name in SCRIPTS:
        module, function = targets[f"fourierf-{name}"].split(":")
        assert module == "fourierf_plugin.launch" and callable(getattr(launch, function)), name
        assert (Path(launch.__file__).parent / "scripts" / f"{name.replace('-', '_')}.py").is_file(), name


@pytest.mark.slow
def test_wheel_holds_every_source_module(wheel: zipfile.ZipFile) -> None:
    """A new subpackage must be added to pyproject's explicit package list, or the wheel silently lacks it."""
    names = set(wheel.namelist())
    missing = [
        f"{prefix}/{path.relative_to(folder).as_posix()}"
        for folder, prefix in SOURCE_FOLDERS.items()
        for path in folder.rglob("*.py")
        if "__pycache__" not in path.parts and f"{prefix}/{path.relative_to(folder).as_posix()}" not in names
    ]
    assert not missing, missing


def test_every_module_imports() -> None:
    # walk_packages follows the file system, where the mapped folders are not below fourierf_plugin/ in an
    # editable install; so each mapped package is walked from its own __path__ as well.
    modules: list[str] = []
    for root in ("fourierf_plugin", *MAPPED):
        package = importlib.import_module(root)
        modules.append(root)
        modules += [i.name for i in pkgutil.walk_packages(package.__path__, prefix=f"{root}.", onerror=_raise)]
    for expected in ("fourierf_plugin.data.parsers.blender", "fourierf_plugin.method_configs.presets"):
        assert expected in modules
    for name in modules:
        importlib.import_module(name)


def test_mapped_packages_come_from_the_top_level_folders() -> None:
    """The installed import names resolve to method_configs/ and data/parsers/ (no shadow copies in the package)."""
    import fourierf_plugin.data.parsers as parsers
    import fourierf_plugin.method_configs as method_configs

    assert Path(parsers.__file__).resolve().parent == (REPO_ROOT / "data" / "parsers").resolve()
    assert Path(method_configs.__file__).resolve().parent == (REPO_ROOT / "method_configs").resolve()
    assert not (REPO_ROOT / "fourierf_plugin" / "data" / "parsers").exists()
    assert not (REPO_ROOT / "fourierf_plugin" / "method_configs").exists()


def _raise(name: str) -> None:
    raise ImportError(f"cannot import {name} while walking fourierf_plugin")


def test_the_package_writes_no_benchmark_report() -> None:
    """BENCHMARKS.md and its sections are written by the scripts in benchmarks/ alone: no installed module names a
    markdown file to write."""
    named = [
        str(path.relative_to(REPO_ROOT))
        for folder in SOURCE_FOLDERS
        for path in folder.rglob("*.py")
        if re.search(r"[\w-]\.md[\"']", path.read_text())
    ]
    assert SOURCE_FOLDERS and not named, named
