"""The thread count reaches every pycolmap stage, matching's totals are COLMAP's pair counts, and the database is
counted while it is written (no pycolmap needed: a stand-in module records the options)."""

from __future__ import annotations

from pathlib import Path
from types import SimpleNamespace

import pytest

from fourierf_plugin.sfm.features import extract_features
from fourierf_plugin.sfm.mapping import run_incremental_mapping
from fourierf_plugin.sfm.matching import exhaustive_block_size, match_features, pair_count


class Options(SimpleNamespace):
    """An options object of pycolmap: any attribute can be set; ``num_threads`` starts at COLMAP's -1."""

    def __init__(self, **kwargs: object) -> None:
        super().__init__(num_threads=-1, sift=SimpleNamespace(), **kwargs)


def fake_pycolmap(calls: dict[str, dict]) -> SimpleNamespace:
    def record(name: str):
        return lambda *args, **kwargs: calls.__setitem__(name, kwargs) or {}

    return SimpleNamespace(
        ImageReaderOptions=Options,
        FeatureExtractionOptions=Options,
        FeatureMatchingOptions=Options,
        ExhaustivePairingOptions=lambda: Options(block_size=50),
        SequentialPairingOptions=Options,
        IncrementalPipelineOptions=lambda: Options(min_model_size=10),
        CameraMode=SimpleNamespace(SINGLE="single", AUTO="auto"),
        Device=SimpleNamespace(cpu="cpu"),
        extract_features=record("extract"),
        match_exhaustive=record("exhaustive"),
        match_sequential=record("sequential"),
        incremental_mapping=record("mapping"),
        set_random_seed=lambda seed: None,
    )


@pytest.mark.parametrize("threads", [None, 3])
def test_threads_reach_extraction_matching_and_mapping(tmp_path: Path, threads: int | None) -> None:
    calls: dict[str, dict] = {}
    pycolmap = fake_pycolmap(calls)
    expected = -1 if threads is None else threads
    extract_features(pycolmap, tmp_path / "db", tmp_path, ["a.png"], threads=threads)  # type: ignore[arg-type]
    assert calls["extract"]["extraction_options"].num_threads == expected
    match_features(pycolmap, tmp_path / "db", "exhaustive", threads=threads, n_images=60)  # type: ignore[arg-type]
    assert calls["exhaustive"]["matching_options"].num_threads == expected
    assert calls["exhaustive"]["pairing_options"].block_size == exhaustive_block_size(60) == 12
    match_features(pycolmap, tmp_path / "db", "sequential", threads=threads)  # type: ignore[arg-type]
    assert calls["sequential"]["matching_options"].num_threads == expected
    assert calls["sequential"]["pairing_options"].num_threads == expected
    assert (
        run_incremental_mapping(pycolmap, tmp_path / "db", tmp_path, tmp_path / "m", ["a.png"], threads=threads) is None
    )  # type: ignore[arg-type]
    assert calls["mapping"]["options"].num_threads == expected


def colmap_sequential_pairs(n: int, overlap: int) -> set[tuple[int, int]]:
    """COLMAP's SequentialPairGenerator with quadratic overlap, written out as it does it."""
    pairs = set()
    for i in range(n):
        for k in range(overlap):
            if i + k + 1 < n:
                pairs.add((i, i + k + 1))
            if i + 2**k < n:
                pairs.add((i, i + 2**k))
    return pairs


@pytest.mark.parametrize("n", [3, 8, 30, 150])
def test_pair_counts_are_the_matchers_totals(n: int) -> None:
    assert pair_count("exhaustive", n) == n * (n - 1) // 2
    assert pair_count("sequential", n) == len(colmap_sequential_pairs(n, 10))
    assert pair_count("sequential", n, overlap=3) == len(colmap_sequential_pairs(n, 3))


def test_block_size_keeps_blocks_small_enough_to_show_progress() -> None:
    assert exhaustive_block_size(8) == 10 and exhaustive_block_size(50) == 10
    assert exhaustive_block_size(120) == 24 and exhaustive_block_size(1000) == 50
