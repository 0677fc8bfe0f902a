"""Properties of the step schedules: cutoff ramp, event steps, lr/L1 weights and grid resolutions."""

from __future__ import annotations

import itertools
import math

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from fourierf_plugin.field_components.schedules import (
    cutoff_at,
    eval_samples_per_ray,
    l1_weight_at,
    last_reset_at,
    lr_scale_at,
    n_to_reso,
    step_size,
    steps_from_fractions,
    train_samples_per_ray,
    tv_weight_at,
    voxel_counts,
)


# ------------------------------------------------------------------------------------------------------ cutoff
def test_cutoff_ramp_endpoints_and_linearity() -> None:
    f0, ramp = 0.3, 2000
    assert cutoff_at(0, f0, ramp) == f0
    assert cutoff_at(ramp, f0, ramp) == 1.0
    assert cutoff_at(ramp + 1, f0, ramp) == 1.0
    assert cutoff_at(10 * ramp, f0, ramp) == 1.0
    assert cutoff_at(1000, f0, ramp) == pytest.approx(0.65)
    values = [cutoff_at(i, f0, ramp) for i in range(0, ramp + 1, 100)]
    diffs = [b - a for a, b in itertools.pairwise(values)]
    assert all(d == pytest.approx(diffs[0]) for d in diffs)  # linear
    assert diffs[0] == pytest.approx(100 * (1 - f0) / ramp)


@settings(max_examples=60, deadline=None)
@given(f0=st.floats(0.0, 1.0), ramp=st.integers(-5, 50_000), a=st.integers(0, 60_000), b=st.integers(0, 60_000))
def test_cutoff_monotone_and_bounded(f0: float, ramp: int, a: int, b: int) -> None:
    lo, hi = sorted((a, b))
    f_lo, f_hi = cutoff_at(lo, f0, ramp), cutoff_at(hi, f0, ramp)
    assert f0 <= f_lo <= f_hi <= 1.0


def test_cutoff_degenerate_cases() -> None:
    assert cutoff_at(0, 0.01, 0) == 1.0  # ramp <= 0: open at once
    assert cutoff_at(5, 0.01, -3) == 1.0
    assert all(cutoff_at(i, 1.0, 1000) == 1.0 for i in (0, 1, 999, 5000))  # f0 = 1: TensoRF baseline
    assert cutoff_at(0, 0.0, 100) == 0.0


def test_cutoff_final_below_one_ends_and_stays_there() -> None:
    f0, ramp, f_final = 0.3, 1000, 0.6
    assert cutoff_at(0, f0, ramp, f_final) == f0
    assert cutoff_at(500, f0, ramp, f_final) == pytest.approx(0.45)  # halfway between f0 and f_final
    assert cutoff_at(ramp, f0, ramp, f_final) == pytest.approx(f_final)
    assert all(cutoff_at(s, f0, ramp, f_final) == f_final for s in (ramp + 1, 10 * ramp))
    assert cutoff_at(0, f0, 0, f_final) == f_final  # no ramp: the final band at once
    assert cutoff_at(7, 0.6, ramp, 0.6) == 0.6  # f0 = f_final: a fixed band


@pytest.mark.parametrize(("f0", "f_final", "match"), [(0.5, 0.4, "above the final"), (0.0, 0.0, "final"),
                                                      (0.1, 1.2, "final"), (0.1, float("nan"), "final")])  # fmt: skip
def test_cutoff_rejects_bad_final(f0: float, f_final: float, match: str) -> None:
    with pytest.raises(ValueError, match=match):
        cutoff_at(0, f0, 100, f_final)


@pytest.mark.parametrize("bad", [-0.01, 1.01, float("nan")])
def test_cutoff_rejects_bad_f0(bad: float) -> None:
    with pytest.raises(ValueError, match="f0"):
        cutoff_at(0, bad, 100)


def test_cutoff_rejects_negative_step() -> None:
    with pytest.raises(ValueError, match="step"):
        cutoff_at(-1, 0.3, 100)


# ------------------------------------------------------------------------------------------------ event steps
def test_steps_from_fractions_places_scales_and_sorts() -> None:
    assert steps_from_fractions([0.1, 0.2333333333], 30_000) == [3000, 7000]
    # The same fractions in a 10k run land at the same relative place.
    assert steps_from_fractions([0.2333333333, 0.1], 10_000) == [1000, 2333]
    assert steps_from_fractions([], 100) == []


def test_steps_from_fractions_deduplicates_collisions() -> None:
    assert steps_from_fractions([0.101, 0.1, 0.099], 100) == [10]


@pytest.mark.parametrize("bad", [0.0, 1.0, 0.001, 0.999, -0.5, 1.5, float("nan")])
def test_steps_from_fractions_rejects_out_of_run(bad: float) -> None:
    with pytest.raises(ValueError, match="fraction"):
        steps_from_fractions([0.5, bad], 100)


# ---------------------------------------------------------------------------------------------- lr and L1
def test_last_reset_at() -> None:
    resets = [2000, 3000, 4000, 7000]
    assert last_reset_at(0, resets) == 0
    assert last_reset_at(1999, resets) == 0
    assert last_reset_at(2000, resets) == 2000
    assert last_reset_at(3500, resets) == 3000
    assert last_reset_at(29_999, resets) == 7000
    assert last_reset_at(5, []) == 0
    assert last_reset_at(4500, [7000, 3000, 4000]) == 4000  # order of the list does not matter


def test_lr_scale_decays_and_resets() -> None:
    max_iters, ratio = 30_000, 0.1
    assert lr_scale_at(0, [], ratio, max_iters) == 1.0
    assert lr_scale_at(max_iters, [], ratio, max_iters) == pytest.approx(ratio)
    assert lr_scale_at(max_iters // 2, [], ratio, max_iters) == pytest.approx(math.sqrt(ratio))
    resets = [2000, 7000]
    assert lr_scale_at(2000, resets, ratio, max_iters) == 1.0
    assert lr_scale_at(7000, resets, ratio, max_iters) == 1.0
    assert lr_scale_at(1999, resets, ratio, max_iters) == pytest.approx(ratio ** (1999 / max_iters))
    assert lr_scale_at(2500, resets, ratio, max_iters) == pytest.approx(ratio ** (500 / max_iters))
    scales = [lr_scale_at(i, resets, ratio, max_iters) for i in range(2000, 7000, 50)]
    assert all(b < a for a, b in itertools.pairwise(scales))


def test_lr_scale_no_decay() -> None:
    assert all(lr_scale_at(i, [2000], 1.0, 10_000) == 1.0 for i in (0, 1999, 2000, 9999, 10_000))


@pytest.mark.parametrize("bad", [0.0, -0.1, float("nan")])
def test_lr_scale_rejects_bad_ratio(bad: float) -> None:
    with pytest.raises(ValueError, match="decay ratio"):
        lr_scale_at(10, [], bad, 100)


def test_tv_weight_decays_like_tensorf_and_ignores_resets() -> None:
    """TensoRF: TV_weight *= 0.1 ** (1 / n_iters) every iteration, so w0 · 0.1 ** (s / n_iters), never restarted."""
    max_iters = 10_000
    assert tv_weight_at(0, 1.0, 0.1, max_iters) == 1.0
    assert tv_weight_at(max_iters // 2, 2.0, 0.1, max_iters) == pytest.approx(2.0 * math.sqrt(0.1), rel=1e-9)
    assert tv_weight_at(max_iters, 1.0, 0.1, max_iters) == pytest.approx(0.1, rel=1e-9)
    # Past an lr reset (upsample at 3000) the lr restarts at 1, the TV weight does not.
    assert lr_scale_at(3000, [3000], 0.1, max_iters) == 1.0
    assert tv_weight_at(3000, 1.0, 0.1, max_iters) == pytest.approx(0.1**0.3, rel=1e-9)
    assert all(tv_weight_at(s, 1.0, 1.0, max_iters) == 1.0 for s in (0, 5000, max_iters)), "ratio 1: no decay"


def test_l1_weight_switch() -> None:
    assert l1_weight_at(0, 2000, 8e-5, 4e-5) == 8e-5
    assert l1_weight_at(1999, 2000, 8e-5, 4e-5) == 8e-5
    assert l1_weight_at(2000, 2000, 8e-5, 4e-5) == 4e-5
    assert l1_weight_at(29_999, 2000, 8e-5, 4e-5) == 4e-5
    assert l1_weight_at(29_999, None, 8e-5, 4e-5) == 8e-5  # no mask update at all


# ------------------------------------------------------------------------------------------------- resolution
def test_voxel_counts_log_spaced_and_exact_end() -> None:
    n0, n1 = 128**3, 300**3
    counts = voxel_counts(n0, n1, 2)
    assert len(counts) == 2
    assert counts[-1] == n1 == 27_000_000  # float32 TensoRF gives 26999994
    assert counts[0] == round(math.sqrt(n0 * n1))  # geometric mean
    assert 195 < counts[0] ** (1 / 3) < 196
    counts5 = voxel_counts(n0, n1, 5)
    ratios = [b / a for a, b in itertools.pairwise([n0, *counts5])]
    assert all(r == pytest.approx(ratios[0], rel=1e-6) for r in ratios)
    assert counts5[-1] == n1
    assert voxel_counts(n0, n1, 0) == []


def test_n_to_reso_cube_does_not_floor_to_127() -> None:
    assert n_to_reso(128**3, [3.0, 3.0, 3.0]) == [128, 128, 128]
    assert n_to_reso(300**3, [3.0, 3.0, 3.0]) == [300, 300, 300]
    assert n_to_reso(2_097_156, [3.0, 3.0, 3.0]) == [128, 128, 128]  # TensoRF's padded init count
    for n in (64, 100, 128, 195, 256, 299):
        for edge in (0.7, 2.6, 3.0, 7.3):
            assert n_to_reso(n**3, [edge] * 3) == [n] * 3


def test_n_to_reso_non_cubic_box_is_proportional() -> None:
    box = [2.0, 3.0, 1.5]
    n = 10_000_000
    reso = n_to_reso(n, box)
    voxel = (math.prod(box) / n) ** (1 / 3)
    assert reso == [math.floor(e / voxel) for e in box]
    assert reso[1] / reso[0] == pytest.approx(1.5, rel=0.01)
    assert reso[2] / reso[0] == pytest.approx(0.75, rel=0.01)
    assert math.prod(reso) == pytest.approx(n, rel=0.02)
    assert math.prod(reso) <= n


def test_n_to_reso_minimum_two_and_validation() -> None:
    assert min(n_to_reso(8, [100.0, 1.0, 1.0])) == 2
    with pytest.raises(ValueError, match="AABB"):
        n_to_reso(1000, [1.0, 0.0, 1.0])
    with pytest.raises(ValueError, match="voxel count"):
        n_to_reso(0, [1.0, 1.0, 1.0])


def test_blender_step_and_sample_counts() -> None:
    box, reso = [3.0, 3.0, 3.0], [128, 128, 128]
    step = step_size(box, reso)
    assert step == pytest.approx(0.5 * 3 / 127)
    assert train_samples_per_ray(reso) == 443
    assert eval_samples_per_ray(box, step) == int(math.sqrt(27) / step) + 1 == 440
    assert step_size([2.0, 4.0], [5, 9], step_ratio=1.0) == pytest.approx(0.5)


def test_step_size_validation() -> None:
    with pytest.raises(ValueError, match=">= 2"):
        step_size([3.0, 3.0, 3.0], [128, 1, 128])
    with pytest.raises(ValueError, match="same length"):
        step_size([3.0, 3.0], [128, 128, 128])
    with pytest.raises(ValueError, match="step"):
        eval_samples_per_ray([3.0, 3.0, 3.0], 0.0)
