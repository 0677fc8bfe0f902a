"""benchmarks/boundary_speed.py: both boundaries timed on the same field, and a report row per cutoff."""

from __future__ import annotations

from tests.helpers import load_benchmark


def test_both_boundaries_are_timed_and_reported_per_cutoff() -> None:
    bench = load_benchmark("boundary_speed")
    periodic, mirror = bench.field([9, 11, 7], False), bench.field([9, 11, 7], True)
    assert not periodic.mirror_boundary and mirror.mirror_boundary
    for a, b in zip(
        periodic.parameters(), mirror.parameters(), strict=True
    ):  # the same field, only the boundary differs
        assert a.equal(b)
    result = bench.measure([9, 11, 7], [0.3, 1.0], repeats=1)
    assert set(result) == {0.3, 1.0} and all(set(by) == {"periodic", "mirror"} for by in result.values())
    assert all(t > 0 for by in result.values() for t in by.values())
    lines = bench.report(result, [9, 11, 7], 1)
    assert lines[-2].startswith("| 0.3 |") and lines[-1].startswith("| 1 |") and lines[-1].endswith("× |")
