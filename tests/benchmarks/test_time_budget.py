"""``benchmarks/time_budget.py``: the table's planned-iterations cell."""

from __future__ import annotations

from tests.helpers import load_benchmark


def test_the_table_shows_the_count_planned_again():
    bench = load_benchmark("time_budget")
    assert bench.planned({"plans": [799, 650, 702], "planned_iterations": 702}) == "799 → 650 → 702"
    assert bench.planned({"plans": [799, 650, 650], "planned_iterations": 650}) == "799 → 650"
    assert bench.planned({"plans": [650, 650], "planned_iterations": 650}) == "650"
    assert bench.planned({"plans": [], "planned_iterations": 650}) == "650"
