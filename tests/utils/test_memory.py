"""Memory guards: the memory a process may use is the smaller of the host's and its cgroup's; grids are checked
initial and final, saved configs are range-checked when read back, and a 16-bit PNG's size is checked from its
header before anything is inflated."""

from __future__ import annotations

import copy
import struct
import zlib
from pathlib import Path

import numpy as np
import pytest

from fourierf_plugin.data import images
from fourierf_plugin.data.images import load_image_rgba
from fourierf_plugin.engine import option_checks
from fourierf_plugin.engine.option_checks import check_grid_fits, check_saved_config
from fourierf_plugin.method_configs import all_methods
from fourierf_plugin.utils import memory
from fourierf_plugin.utils.errors import UserError
from fourierf_plugin.utils.memory import GiB, available_memory, cgroup_available

MiB = 2**20


def files(root: Path, contents: dict[str, str]) -> Path:
    for name, text in contents.items():
        (root / name).parent.mkdir(parents=True, exist_ok=True)
        (root / name).write_text(text)
    return root


def test_a_cgroup_v2_limit_leaves_its_limit_less_the_memory_in_use(tmp_path: Path) -> None:
    root = files(
        tmp_path / "cg",
        {
            "memory.max": f"{GiB}\n",
            "memory.current": f"{600 * MiB}\n",
            "memory.stat": f"anon 1\ninactive_file {100 * MiB}\n",
        },
    )
    proc = files(tmp_path, {"proc_cgroup": "0::/\n"}) / "proc_cgroup"
    assert cgroup_available(root, proc) == GiB - 500 * MiB


def test_the_tightest_of_a_cgroup_and_its_parents_counts(tmp_path: Path) -> None:
    root = files(
        tmp_path / "cg",
        {
            "memory.max": "max\n",
            "jobs/memory.max": f"{2 * GiB}\n",
            "jobs/memory.current": "0\n",
            "jobs/run/memory.max": "max\n",
            "jobs/run/memory.current": f"{GiB}\n",
        },
    )
    proc = files(tmp_path, {"proc_cgroup": "0::/jobs/run\n"}) / "proc_cgroup"
    assert cgroup_available(root, proc) == 2 * GiB


def test_a_cgroup_v1_limit_is_read_and_its_no_limit_value_ignored(tmp_path: Path) -> None:
    root = files(
        tmp_path / "cg",
        {
            "memory/box/memory.limit_in_bytes": f"{3 * GiB}\n",
            "memory/box/memory.usage_in_bytes": f"{GiB}\n",
            "memory/memory.limit_in_bytes": "9223372036854771712\n",
        },
    )
    proc = files(tmp_path, {"proc_cgroup": "4:memory:/box\n0::/\n"}) / "proc_cgroup"
    assert cgroup_available(root, proc) == 2 * GiB
    (root / "memory/box/memory.limit_in_bytes").write_text("9223372036854771712\n")
    assert cgroup_available(root, proc) is None


def test_no_cgroup_files_mean_no_cgroup_limit(tmp_path: Path) -> None:
    assert cgroup_available(tmp_path / "none", tmp_path / "no_proc") is None


def test_the_available_memory_is_the_smaller_of_host_and_cgroup(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(memory, "host_available", lambda: 64 * GiB)
    monkeypatch.setattr(memory, "cgroup_available", lambda: 2 * GiB)
    assert available_memory() == 2 * GiB
    monkeypatch.setattr(memory, "cgroup_available", lambda: None)
    assert available_memory() == 64 * GiB


def test_an_initial_grid_larger_than_the_final_one_is_checked_and_named() -> None:
    config = copy.deepcopy(all_methods["fourierf-vm"])
    config.pipeline.model.field.n_voxels_init = 10**12
    with pytest.raises(UserError) as info:
        check_grid_fits(config, available=8 * GiB)
    assert "initial grid (--pipeline.model.field.n-voxels-init 1000000000000)" in info.value.problem
    assert "--pipeline.model.field.n-voxels-init" in (info.value.fix or "")


def test_a_saved_config_out_of_range_names_the_file_and_the_value(tmp_path: Path) -> None:
    config = copy.deepcopy(all_methods["fourierf-vm"])
    config.pipeline.model.step_ratio = -1.0
    with pytest.raises(UserError) as info:
        check_saved_config(config, tmp_path / "config.json")
    assert "config.json holds a value out of range" in info.value.problem and "step-ratio -1.0" in info.value.problem


def test_a_saved_grid_is_checked_with_one_copy_of_its_values(monkeypatch: pytest.MonkeyPatch, tmp_path: Path) -> None:
    config = copy.deepcopy(all_methods["fourierf-vm"])
    one_copy = option_checks.grid_values(config.pipeline.model.field, config.pipeline.model.field.n_voxels_final) * 4
    monkeypatch.setattr(memory, "available_memory", lambda: int(one_copy * 1.5))
    check_saved_config(config, tmp_path / "config.json")  # fits once, though not six times as in training
    monkeypatch.setattr(memory, "available_memory", lambda: int(one_copy / 2))
    with pytest.raises(UserError, match="more memory"):
        check_saved_config(config, tmp_path / "config.json")


def png16(path: Path, width: int, height: int, pixel_bytes: bytes) -> Path:
    def chunk(kind: bytes, body: bytes) -> bytes:
        return struct.pack(">I", len(body)) + kind + body + struct.pack(">I", zlib.crc32(kind + body))

    header = struct.pack(">IIBBBBB", width, height, 16, 0, 0, 0, 0)  # 16-bit gray
    path.write_bytes(
        b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", header) + chunk(b"IDAT", zlib.compress(pixel_bytes)) + chunk(b"IEND", b"")
    )
    return path


def test_a_16bit_png_over_the_pixel_limit_is_refused_before_inflating(tmp_path: Path) -> None:
    path = png16(tmp_path / "bomb.png", 100_000, 100_000, bytes(100))
    with pytest.raises(UserError, match="decompression bomb"):
        load_image_rgba(path)


def test_a_16bit_png_that_cannot_be_decoded_in_memory_is_refused(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    path = png16(tmp_path / "big.png", 4000, 4000, bytes(10))
    monkeypatch.setattr(memory, "available_memory", lambda: 100 * MiB)
    with pytest.raises(UserError, match="decoding the 4000x4000 16-bit image"):
        load_image_rgba(path)


def test_a_16bit_png_inflates_no_further_than_its_header_says(tmp_path: Path) -> None:
    row = b"\x00" + (1000).to_bytes(2, "big") * 3  # filter byte, three 16-bit gray pixels
    path = png16(tmp_path / "padded.png", 3, 2, row * 2 + bytes(50_000_000))  # 50 MB of trailing zeros
    pixels = images._read_png16(path)
    assert pixels.shape == (2, 3) and np.all(pixels == 1000)
