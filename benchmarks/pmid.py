"""Few-shot quality at two budgets, P-CPU and P-MID: fourierf-vm against tensorf-vm, each at val-chosen settings.

Why two budgets: the paper's claim is that the curriculum pays where TensoRF overfits (bigger grids, more iterations,
finer images). P-CPU is the budget a user runs on a CPU by default; P-MID is the largest that still trains in about
20 minutes on a 2-core CPU (the cost estimate of ``engine.estimates``: 3000 × 2048 rays × 192 × 1.05e-6 s ≈ 21 min;
lego took 24-45 min a run, two at a time with one thread each), so the gain-versus-scale trend can be read off one
table.

| protocol | iterations | rays | grid | lego (4 views 27 76 97 99) | fern (3 views 1 10 19) |
|---|---|---|---|---|---|
| P-CPU | 800 | 1024 | 64³ → 128³ | 100×100 | 504×378 (images_8) |
| P-MID | 3000 | 2048 | 96³ → 192³ | 200×200 | 504×378 (images_8) |
| P-CPU sizes, 3000 it. (curve) | 3000 | 1024 | 64³ → 128³ | 100×100 | 504×378 (images_8) |
| P-CPU sizes, 1500 it. (the rule between) | 1500 | 1024 | 64³ → 128³ | 100×100 | 504×378 (images_8) |
| P-HIGH (lego only) | 3000 | 2048 | 128³ → 300³ | 400×400 | — |
| P-MID images, 300³ (lego only) | 3000 | 2048 | 128³ → 300³ | 200×200 | — |

P-MID's final grid is what the CPU run sizing picks for these images (1.28 voxels per pixel of the larger side, capped
at 192). TensoRF's LLFF configuration grows to 640³ over 25k iterations at 1/4 resolution and the paper's Blender
protocol to 300³ at 800×800: neither fits a CPU's 20 minutes, and at 200×200 or 504×378 a 192³ grid already holds more
voxels along each axis than the images have pixels across the scene.
P-HIGH (session 32) goes one step toward the paper's Blender protocol where a CPU still can: lego at the shared data's
full 400×400 with the paper's grids (128³ → 300³), at P-MID's iterations and rays; 35-45 minutes of training a run,
two at a time with one thread each (``--threads`` caps the evaluations too): TV searched on one seed, each choice
and the stronger TVs next to it on three (sessions 36-39; tensorf-vm's TV 16 on two). tensorf-vm's search ran on
TensoRF's 16 / 48 components (settings without ``comp8`` pass none, and ``--budget-rule False`` keeps the
preset's), fourierf-vm's on the object rule's 8 / 24; on 8 / 24 tensorf-vm's TV 12 (sessions 40-43: TV 10-16 on one
seed, 12 and 14 on three) is its val choice, level with fourierf-vm.
``pmid300`` (sessions 33-35) is P-HIGH's grids on P-MID's images, the 300³ final grid the issue's example P-MID names
(41-58 minutes of training a run here, 3.5 on an H100 four at a time, so three seeds): which of P-HIGH's two changes
opens the curriculum's edge. There too tensorf-vm's val choice is on 8 / 24 (TV 10, sessions 41-44), +0.24 dB test
behind fourierf-vm (+0.50 while its TV 12 alone had run on three seeds).

Settings are chosen on validation views only (lego: every 8th of Blender's val split; fern: training images no run
trains on, 2 9 18); the test views (lego every 8th test view, fern 0 8 16) are evaluated for every run but only the
val-chosen setting's test score is reported. Stages:

    python benchmarks/pmid.py sweep  --protocol pcpu pmid --scene lego fern   # every setting, first seed
    python benchmarks/pmid.py seeds  --protocol pcpu pmid --scene lego fern   # the val-chosen setting, more seeds
    python benchmarks/pmid.py seeds  --protocol pmid --scene lego --seeds 1   # one later seed at a time (long runs)
    python benchmarks/pmid.py curve  --scene fern     # P-CPU sizes at 3000 iterations, a checkpoint every 500 evaluated
    python benchmarks/pmid.py sweep  --only S --again "threads not recorded"  # run recorded runs again (repeats.jsonl)
    python benchmarks/pmid.py merge  --rows lane2/results.jsonl --again "threads not recorded"  # rows run elsewhere
    python benchmarks/pmid.py report                                          # BENCHMARKS.md section

Rows go to ``benchmarks/results/pmid/results.jsonl`` (committed; a recorded run is skipped, so the report is
regenerated from it alone). ``--device cuda --jobs 4`` runs four trainings at once on one GPU (each with
``--threads``; sixteen at once time-slice it to a crawl); the PSNRs do not depend on the device beyond float rounding
and random streams, the times do (the table names the device). GPU runs are not bit-reproducible (grid_sample's CUDA
backward accumulates with atomics): where a key is run again (``--again NOTE``), its earlier row moves to
``repeats.jsonl`` beside the results with NOTE as its ``repeat`` note, and the report sets both side by side. Nor is
a CPU run on more than one thread (torch's parallel CPU kernels sum in a varying order; session 48: two 2-thread fern
runs differed from step 40, and fern P-CPU tensorf-vm with Floaters-No-More, seed 20211202, read val 20.46 on two
threads, 20.14 on one and 20.70 in its recorded row, which did not record its threads). On one thread, the default,
it is: that run's training trace at commit 71362f1 and at session 48's code agreed to the printed digit, and session
49's rerun read 20.14 again. Rows record their training's thread count (``train_threads``) and, where the density can
revive, the batches it revived (``revived_batches``; 0: the run is TensoRF's ReLU to the bit).
"""

from __future__ import annotations

import argparse
import json
import sys
import threading
from collections.abc import Iterable, Sequence
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from fourierf_plugin.bench.protocol import (
    Run,
    evaluate,
    fmt,
    load_results,
    save_results,
    section_head,
    train_and_eval,
    update_benchmarks_md,
)

REPO = Path(__file__).resolve().parents[1]
BEGIN = "<!-- pmid:begin (generated by benchmarks/pmid.py; do not edit) -->"
END = "<!-- pmid:end -->"
METHODS = ("fourierf-vm", "tensorf-vm")


@dataclass(frozen=True)
class Grid:
    """A picture grid of two test views (``benchmarks/picture_grid.py``) and what it shows."""

    path: str
    runs: str
    """Which runs its columns render, in words."""
    columns: tuple[str, ...]
    reading: str
    """What the grid shows, read by eye (not measured)."""
    heading: str = "Why fern ghosts"
    scene: str = "fern"
    views: str = "test views 0 and 8"


GRIDS = (
    Grid(
        "docs/fern_grid_pcpu.png",
        "P-CPU runs fourierf-vm `lr0.08-tvconst` and tensorf-vm `lr0.08`, each method's val choice when it was made, "
        "both at TV 1",
        ("fourierf-vm", "tensorf-vm"),
        "both runs are opaque everywhere (accumulation 1), so nothing is left empty. tensorf-vm's depth is broken into "
        "patches, many at the near end: density painted just in front of the cameras reproduces each training photo "
        "and shows as ghosted, doubled leaves and smeared background from a new view. fourierf-vm's depth is one "
        "smooth layer, the plant in front of the planter and the wall behind, with far fewer near patches; its "
        "remaining error is blur (the band limit) and a faint doubled frond at the left edge, seen by a single "
        "training view. The occlusion term at FreeNeRF's strength is what keeps tensorf-vm's near patches in check at "
        "all (val 15.92 dB without it, 18.39 with it).",
    ),
    Grid(
        "docs/fern_grid_pmid.png",
        "P-MID runs of session 25 under the current rule, each method's val choice at P-MID then (since session 56 "
        "fourierf-vm's is the same setting with Floaters-No-More from step 800, by 0.12 dB of mean val over 3 "
        "seeds): fourierf-vm `lr0.08-tvconst-ramp0.2667-tv4-revive1` (val / test 21.84 / 20.99; its recorded run of "
        "session 23, 21.66 / 20.92) and tensorf-vm `lr0.08-tvconst-tv4-fnm` (constant TV 4 with Floaters-No-More; "
        "21.90 / 21.12, recorded 21.89 / 21.14), seed 20211202, CPU",
        ("fourierf-vm", "tensorf-vm"),
        "both are opaque everywhere. tensorf-vm's RGB is the sharper of the two (the fronds). fourierf-vm's depth is "
        "one smooth layer for the plant but holds a near blob at the foot of the trunk (dark, in both views) and a "
        "few near streaks at the top left; its RGB is softer (the band limit). The blob is no floater (session 29, "
        "`benchmarks/point_probe.py`): it is the frond that hangs over the planter, which all three training views "
        "see at NDC (-0.48, -0.80, -0.34) and both runs render at that depth there (0.34-0.35 and 0.33-0.36 for the "
        "point's 0.33), fourierf-vm's as a blob wider than the frond, tensorf-vm's as the thin streak it is. Where "
        "tensorf-vm errs it errs far: broken "
        "patches of far depth over the ceiling and the wall at the top left. The curriculum and Floaters-No-More both "
        "keep fern from ghosting at this scale; the gradient scaling does it without blurring.",
    ),
    Grid(
        "docs/fern_grid_boundary.png",
        "P-CPU runs of session 29, seed 20211202: fourierf-vm on the forward-facing rule `lr0.08-tvconst-tv4-"
        "alphamask0.25` (val / test 20.08 / 19.47), the same with mirror boundaries `...-mirror` (20.15 / 19.68), and "
        "tensorf-vm with Floaters-No-More `lr0.08-tvconst-tv4-fnm-alphamask0.25` (20.39 / 19.73)",
        ("fourierf-vm", "fourierf-vm mirror", "tensorf-vm + FNM"),
        "all three are opaque everywhere. With periodic filters fourierf-vm holds a near blob at the foot of the "
        "planter (dark, both views): the frond that hangs over it, widened by the band limit. It is a real surface "
        "(`benchmarks/point_probe.py --point -0.48 -0.80 -0.34`): all three training views see that point on the "
        "frond (green pixels between white planter) and fourierf-vm renders them at its depth (0.335 for 0.330), "
        "while tensorf-vm with Floaters-No-More renders the same training rays at 0.45-0.55: at this grid it paints "
        "the frond onto the planter (test view 0, row 340: the frond's pixels at 0.44-0.67 beside a planter at "
        "0.44-0.47; fourierf-vm's at 0.35-0.36 over twice the frond's width), which the gradient scaling favours by "
        "slowing near density. So the blob is a geometry fourierf-vm gets nearly right and too wide, not a floater. "
        "Mirror boundaries leave it on seeds 1 and 2 (nearest depth of test view 0's "
        "lower left 0.36 and 0.33 against 0.33 periodic; 0.46 on this seed) and otherwise change little: a few near "
        "spots at the top edge, the plant one smooth layer, the wall at the right far.",
    ),
    Grid(
        "docs/fern_grid_pcpu_rule.png",
        "P-CPU runs of session 47, seed 20211202, each method's P-CPU val choice under today's code: fourierf-vm on "
        "the 800-iteration rule `lr0.08-tvconst-tv6-alphamask0.25-zfree` (val / test 20.51 / 19.96, as recorded) and "
        "tensorf-vm with Floaters-No-More `lr0.08-tvconst-tv4-fnm` (20.14 / 19.48; its recorded run, commit 71362f1, "
        "20.70 / 19.97)",
        ("fourierf-vm", "tensorf-vm + FNM"),
        "both are opaque everywhere. fourierf-vm's RGB is the softer (the band limit), its depth one layer for the "
        "plant and the planter, the wall at the right and a few patches at the top left far, and the frond over the "
        "planter's foot near (the blob of the grids above). tensorf-vm's RGB is the sharper, but its depth holds large "
        "near blobs where the far wall is (right, both views) and over the trunk's middle, and near streaks along the "
        "ceiling: density painted in front of the cameras that reproduces the training photos and, from these test "
        "views close to them, still reads as the wall's colour. Floaters-No-More slows near density; it does not "
        "stop it.",
    ),
    Grid(
        "docs/lego_grid_phigh.png",
        "P-HIGH runs of session 32, seed 20211202, each method's val choice there: fourierf-vm "
        "`wd0-nodecay-lr0.04-tv4-comp8-bgwarm` (val / test 22.37 / 22.43) and tensorf-vm "
        "`wd0-nodecay-lr0.04-tv10-bgwarm` (21.47 / 21.30); `--view-names r_0 r_80`",
        ("fourierf-vm", "tensorf-vm"),
        "both fill the object and leave the background empty. From the front (r_0) tensorf-vm's accumulation has a "
        "dark seam along the left track where fourierf-vm's is whole (both show a few specks at the baseplate's front "
        "edge). From the side (r_80) both hang a skirt of density below the baseplate, which no training view sees "
        "from below, tensorf-vm's "
        "longer; tensorf-vm has floaters beside the bucket arm and the cab and renders the tracks as a dark smear, "
        "where fourierf-vm's tracks keep their outline. Both depths are one layer; the difference is in the edges.",
        "What the gap looks like at P-HIGH",
        "lego",
        "test views r_0 and r_80",
    ),
    Grid(
        "docs/lego_grid_phigh_seed2.png",
        "P-HIGH runs of seed 2, where tensorf-vm at its one-seed choice fell furthest: fourierf-vm "
        "`wd0-nodecay-lr0.04-tv4-comp8-bgwarm` (val / test 22.23 / 22.00; session 36) and `...-tv8-comp8-bgwarm` "
        "(22.50 / 22.57, session 37; level over three seeds with TV 12, the val choice by 0.01 dB since session 39), "
        "tensorf-vm `wd0-nodecay-lr0.04-tv10-bgwarm` (20.64 / 19.75; session 36), `...-tv12-bgwarm` (21.88 / 21.45; "
        "session 37) and `...-tv14-bgwarm` (22.40 / 22.10, the three-seed val choice on TensoRF's 16 / 48 "
        "components; session 38; tensorf-vm's three runs here all on 16 / 48); "
        "`--view-names r_56 r_152`, the two test views with the largest gaps at "
        "the one-seed choices (4.1 and 4.5 dB); there fourierf-vm TV 4, TV 8 read 22.67, 24.37 and 24.50, 26.01 dB, "
        "tensorf-vm TV 10, TV 12, TV 14 18.54, 22.76, 23.73 and 20.05, 24.72, 26.17",
        ("fourierf-vm TV 4", "fourierf-vm TV 8", "tensorf-vm TV 10", "tensorf-vm TV 12", "tensorf-vm TV 14"),
        "all five leave a hole where the left track should be in r_56. At TV 10 tensorf-vm "
        "hangs a detached lump of density beside the bucket in both views and fills the hole and the cab with dark, "
        "near patches in depth (density floating in front of the object); at TV 12 the lump is a speck and fewer "
        "near patches remain (two over the tracks in r_152), about as many as fourierf-vm's at TV 4; at TV 14 "
        "tensorf-vm, like fourierf-vm at TV 8, shows no lump and no near patch in either view. On these two views a "
        "strong enough TV removes the floaters of both methods; fourierf-vm needs about half TensoRF's TV for it.",
        "What the gap looks like at P-HIGH: seed 2, TensoRF at TV 10, 12 and 14",
        "lego",
        "test views r_56 and r_152",
    ),
)

SEEDS = (20211202, 1, 2)


@dataclass(frozen=True)
class Protocol:
    name: str
    """How the report names it."""
    iters: int
    rays: int
    init_side: int
    final_side: int
    lego_downscale: int

    def flags(self) -> list[str]:
        return [
            "--pipeline.datamanager.rays-per-batch", str(self.rays),
            "--pipeline.model.field.n-voxels-init", str(self.init_side**3),
            "--pipeline.model.field.n-voxels-final", str(self.final_side**3),
            "--steps-per-save", "100000",
        ]  # fmt: skip


PROTOCOLS = {  # name, iterations, rays per batch, initial and final grid side, lego downscale
    "pcpu": Protocol("P-CPU", 800, 1024, 64, 128, 4),
    "pmid": Protocol("P-MID", 3000, 2048, 96, 192, 2),
    # P-MID's sizes at P-CPU's 800 iterations: does quality hold as the budget grows from 800 to 3000?
    "pmid800": Protocol("P-MID sizes, 800 it.", 800, 2048, 96, 192, 2),
    # P-CPU at 1.3 × its iterations: the wall time of a final cutoff 0.7 at 800 (ab_speed), for an equal-time check.
    "pcpu1040": Protocol("P-CPU, 1040 it.", 1040, 1024, 64, 128, 4),
    # Between 800 and 1040 (session 63): where the object rule's first band of 0.05 (won at 800) stops paying; session
    # 64: it won at both, so the rule takes it up to 1000 iterations.
    "pcpu900": Protocol("P-CPU sizes, 900 it.", 900, 1024, 64, 128, 4),
    "pcpu1000": Protocol("P-CPU sizes, 1000 it.", 1000, 1024, 64, 128, 4),
    # P-CPU's sizes at P-MID's 3000 iterations, for the curve along training (the ``curve`` stage only).
    "pcpu3000": Protocol("P-CPU sizes, 3000 it.", 3000, 1024, 64, 128, 4),
    # Between the two: where the budget rule's revival at once (over 800 iterations) starts to pay (fern), and whether
    # P-CPU's val choices carry past 800 iterations (lego, session 27).
    "pcpu1500": Protocol("P-CPU sizes, 1500 it.", 1500, 1024, 64, 128, 4),
    # Toward the paper's Blender protocol (128³ → 300³ at 800×800; session 32): lego at the shared data's full 400×400
    # with the paper's grids, P-MID's iterations and rays. Does the curriculum's edge grow with the image and grid?
    "phigh": Protocol("P-HIGH (lego 400×400, 300³)", 3000, 2048, 128, 300, 1),
    # P-MID's images with P-HIGH's grids (the example P-MID names a 300³ final grid; session 33): of
    # P-HIGH's two changes from P-MID, is it the finer grid or the finer images that opens the curriculum's edge?
    "pmid300": Protocol("P-MID images, 300³ (lego 200×200)", 3000, 2048, 128, 300, 2),
}
PROTOCOL_SCENES = {"pmid800": ("fern",), "phigh": ("lego",), "pmid300": ("lego",)}
"""The protocols that measure one scene only (the sweep skips the other)."""
CURVE_BASE = {"pcpu3000": "pcpu", "pmid": "pmid800"}
"""A curve's protocol and the 800-iteration protocol of the same sizes, whose val-chosen setting the curve trains."""
CURVE_EVERY = 500
"""Iterations between the checkpoints a curve evaluates."""

WD0 = ["--optimizer.weight-decay", "0"]
NO_DECAY = ["--optimizer.lr-decay-ratio", "1.0"]
TV_CONST = ["--pipeline.model.tv-decay-ratio", "1.0"]
OCC_ON = ["--pipeline.effects.occlusion-regularization", "True"]
RAMP = "--pipeline.model.fourier.ramp-fraction"
F_FINAL = "--pipeline.model.fourier.f-final"
F_FINAL_COLOR = "--pipeline.model.fourier.f-final-color"
F0_DENSITY, F0_COLOR = "--pipeline.model.fourier.f0-density", "--pipeline.model.fourier.f0-color"
FNM = ["--pipeline.model.floaters-gradient-scaling", "True"]
FNM_FROM = "--pipeline.model.floaters-gradient-scaling-from"
IN_BAND = ["--pipeline.model.fourier.init-in-band", "True"]
LATE_ALPHA_MASK = ["--pipeline.model.occupancy-update-fractions", "0.3", "0.5"]
"""The occupancy grid's two updates at 30 % and 50 % of the run (the object default: 20 % and 40 %)."""
RANDOM_BACKGROUND = ["--pipeline.effects.background", "random", "--pipeline.model.random-background-from", "0"]
"""A random colour behind each training ray from the first step (sessions 26-30; the flag pins it since session 30)."""
RANDOM_AFTER_UPDATE = ["--pipeline.effects.background", "random"]
"""A random training background from the step after the first occupancy update, white before (session 30)."""
MIRROR = ["--pipeline.model.fourier.boundary", "mirror"]
L1_OFF = ["--pipeline.model.l1-weight-initial", "0", "--pipeline.model.l1-weight-rest", "0"]
L1_LATE = ["--pipeline.model.l1-weight-initial", "0"]
"""No density L1 before the first occupancy update (TensoRF's 4e-5 from there on)."""
OCCUPANCY_AT_STEP_200 = ["--pipeline.model.occupancy-update-fractions", "0.25"]
"""A forward-facing run's one occupancy update at 25 % of 800 iterations, step 200 (the real preset: 10 %, step 80)."""
EARLY_FINAL_GRID = ["--pipeline.model.field.upsample-fractions", "0.01"]
"""One upsample at 1 % of the run: the field holds the final grid from step 8 (at 800 iterations) on."""
RULE_LEGO = [*WD0, *NO_DECAY, "--optimizer.lr-grids", "0.04"]
REVIVE1 = ["--pipeline.model.field.revive-patience", "1"]
PLAIN_RELU = ["--pipeline.model.field.revive-dead-density", "False"]
DENSITY_XY = ["--pipeline.model.fourier.density-axes", "0", "1"]
"""The density curriculum on the image plane only: NDC depth (z) unfiltered from the first step (session 45)."""


def tv_weights(weight: float) -> list[str]:
    """Both TV weights (density and appearance planes) at ``weight``."""
    return ["--pipeline.model.tv-weight-density", str(weight), "--pipeline.model.tv-weight-appearance", str(weight)]


def fern_rule(ramp: str, tv: float = 4.0, lr: str = "0.08") -> list[str]:
    """The forward-facing rule's flags with the band open by ``ramp`` of the run: grid lr, constant TV at ``tv``."""
    return ["--optimizer.lr-grids", lr, *TV_CONST, RAMP, ramp, *tv_weights(tv)]


FERN_PMID_RULE = fern_rule("0.2667")
"""Session 19's forward-facing rule at 3000 iterations (the band open by step 800, constant TV 4), which P-MID's fern
settings of sessions 19, 23 and 24 vary."""


def fern_tv(tv: float, lr: str = "0.08") -> list[str]:
    """The forward-facing rule at 800 iterations with a constant TV weight ``tv`` at grid lr ``lr`` (the preset's
    band)."""
    return ["--optimizer.lr-grids", lr, *TV_CONST, *tv_weights(tv)]


def fern_short(tv: float, lr: str = "0.08") -> list[str]:
    """``fern_tv`` with the occupancy update at step 200: tensorf-vm's forward-facing rule at 800 iterations."""
    return [*fern_tv(tv, lr), *OCCUPANCY_AT_STEP_200]


def fern_image_plane(tv: float, lr: str = "0.08") -> list[str]:
    """``fern_short`` with the density curriculum on the image plane: fourierf-vm's forward-facing rule at 800
    iterations since session 45 (TV 6 since session 46)."""
    return [*fern_short(tv, lr), *DENSITY_XY]


FERN_TV4 = fern_tv(4.0)
"""The forward-facing rule at 800 iterations (grid lr 0.08, constant TV 4; the preset's band), which P-CPU's fern
settings of sessions 16-26 vary."""


def first_band(f0: str) -> list[str]:
    """Both grids' first band (``f0`` of the spectrum kept at step 0)."""
    return [F0_DENSITY, f0, F0_COLOR, f0]


def components(density: int, appearance: int) -> list[str]:
    """Component counts per plane/line group (TensoRF's are 16 for density and 48 for appearance)."""
    return [
        "--pipeline.model.field.density-components", *[str(density)] * 3,
        "--pipeline.model.field.appearance-components", *[str(appearance)] * 3,
    ]  # fmt: skip


def grid(init_side: int, final_side: int) -> list[str]:
    """The initial and final grid (later flags win over the protocol's own sizes)."""
    return [
        "--pipeline.model.field.n-voxels-init", str(init_side**3),
        "--pipeline.model.field.n-voxels-final", str(final_side**3),
    ]  # fmt: skip


def depth_smoothness(weight: float) -> list[str]:
    """RegNeRF's depth smoothness at ``weight`` on the default unseen-view patches (4 of 8×8 pixels a step)."""
    return ["--pipeline.model.depth-smoothness-weight", str(weight)]


def occlusion(weight: str) -> list[str]:
    """FreeNeRF's occlusion term at ``weight`` (the preset's 0.01; 0 = off)."""
    return ["--pipeline.model.occlusion-weight", weight]


def distortion(weight: str) -> list[str]:
    """mip-NeRF 360's distortion loss at ``weight`` on the training rays."""
    return ["--pipeline.model.distortion-weight", weight]


def entropy(weight: str, unseen_rays: int | None = None) -> list[str]:
    """InfoNeRF's ray entropy at ``weight`` on the training rays and ``unseen_rays`` (default 1024) unseen rays."""
    rays = [] if unseen_rays is None else ["--pipeline.model.entropy-unseen-rays", str(unseen_rays)]
    return ["--pipeline.model.entropy-weight", weight, *rays]


TV_LOW = tv_weights(0.1)
LEGO_TV4 = [*RULE_LEGO, *tv_weights(4.0)]
"""The object rule of sessions 16-26 (TV 4), which the lego settings of sessions 20 and 25-27 vary; since session 27
the rule also has half the components (``...-tv4-comp8``)."""
LEGO_COMP8 = [*LEGO_TV4, *components(8, 24)]
"""``LEGO_TV4`` with half TensoRF's components (8 density, 24 appearance): ``...-tv4-comp8``."""
LEGO_BGWARM = [*LEGO_COMP8, *RANDOM_AFTER_UPDATE]
"""``LEGO_COMP8`` on a random background from the first occupancy update on: ``...-tv4-comp8-bgwarm``, the object
rule's settings today."""
SETTINGS: dict[str, dict[str, list[str]]] = {
    # Object scenes: the synthetic preset and the levers the issue names (weight decay, lr decay, TV, f0/Δ).
    "lego": {
        "preset": [],
        "wd0": WD0,
        "wd0.05": ["--optimizer.weight-decay", "0.05"],
        "wd0-nodecay": WD0 + NO_DECAY,
        "wd0-tv0.1": [*WD0, *TV_LOW],
        "wd0-tvconst": [*WD0, *TV_CONST],
        "wd0-lr0.04": [*WD0, "--optimizer.lr-grids", "0.04"],
        "wd0-ramp0.5": [*WD0, "--pipeline.model.fourier.ramp-fraction", "0.5"],
        "wd0-f0.1": [*WD0, *first_band("0.1")],
        # Session 12: the levers left, on the val-chosen wd0-nodecay (a longer ramp, a final cutoff below 1, the
        # occlusion term on an object).
        "wd0-nodecay-ramp0.5": [*WD0, *NO_DECAY, RAMP, "0.5"],
        "wd0-nodecay-ramp0.8": [*WD0, *NO_DECAY, RAMP, "0.8"],
        "wd0-nodecay-ffinal0.7": [*WD0, *NO_DECAY, F_FINAL, "0.7"],
        "wd0-nodecay-ffinal0.5": [*WD0, *NO_DECAY, F_FINAL, "0.5"],
        "wd0-nodecay-occ": [*WD0, *NO_DECAY, *OCC_ON],
        "wd0-nodecay-ramp0.5-ffinal0.7": [*WD0, *NO_DECAY, RAMP, "0.5", F_FINAL, "0.7"],
        # Session 14: the grid learning rate, a wider first band, lighter TV, on the rule's optimiser.
        "wd0-nodecay-lr0.04": [*WD0, *NO_DECAY, "--optimizer.lr-grids", "0.04"],
        "wd0-nodecay-lr0.01": [*WD0, *NO_DECAY, "--optimizer.lr-grids", "0.01"],
        "wd0-nodecay-f0.5": [*WD0, *NO_DECAY, *first_band("0.5")],
        "wd0-nodecay-tv0.1": [*WD0, *NO_DECAY, *TV_LOW],
        "wd0-nodecay-lr0.04-ramp0.5": [*WD0, *NO_DECAY, "--optimizer.lr-grids", "0.04", RAMP, "0.5"],
        # Session 15: the curriculum's own levers on the rule's settings (density and colour bands apart, a longer
        # ramp, a final cutoff), and a higher grid lr for both.
        "wd0-nodecay-lr0.04-ramp0.5-f0d0.1": [*RULE_LEGO, RAMP, "0.5", F0_DENSITY, "0.1"],
        "wd0-nodecay-lr0.04-ramp0.5-f0c0.1": [*RULE_LEGO, RAMP, "0.5", F0_COLOR, "0.1"],
        "wd0-nodecay-lr0.04-ramp0.65": [*RULE_LEGO, RAMP, "0.65"],
        "wd0-nodecay-lr0.04-ramp0.5-ffinal0.85": [*RULE_LEGO, RAMP, "0.5", F_FINAL, "0.85"],
        "wd0-nodecay-lr0.06": [*WD0, *NO_DECAY, "--optimizer.lr-grids", "0.06"],
        "wd0-nodecay-lr0.06-ramp0.5": [*WD0, *NO_DECAY, "--optimizer.lr-grids", "0.06", RAMP, "0.5"],
        "wd0-nodecay-lr0.04-ramp0.8": [*RULE_LEGO, RAMP, "0.8"],
        "wd0-nodecay-lr0.04-ramp1": [*RULE_LEGO, RAMP, "1.0"],
        "wd0-nodecay-lr0.04-ramp0.65-ffinal0.85": [*RULE_LEGO, RAMP, "0.65", F_FINAL, "0.85"],
        # The geometry alone band-limited for good (appearance opens fully): a quarter of the filtering's cost.
        "wd0-nodecay-lr0.04-ramp0.5-ffinald0.7": [*RULE_LEGO, RAMP, "0.5", F_FINAL, "0.7", F_FINAL_COLOR, "1.0"],
        "wd0-nodecay-lr0.04-ramp0.5-ffinald0.5": [*RULE_LEGO, RAMP, "0.5", F_FINAL, "0.5", F_FINAL_COLOR, "1.0"],
        # TV weight around the preset's 1.0 (0.1 lost 2 dB), for both methods at the rule's grid lr.
        "wd0-nodecay-lr0.04-tv2": [*RULE_LEGO, *tv_weights(2.0)],
        "wd0-nodecay-lr0.04-ramp0.5-tv2": [*RULE_LEGO, RAMP, "0.5", *tv_weights(2.0)],
        "wd0-nodecay-lr0.04-tv0.5": [*RULE_LEGO, *tv_weights(0.5)],
        "wd0-nodecay-lr0.04-ramp0.5-tv0.5": [*RULE_LEGO, RAMP, "0.5", *tv_weights(0.5)],
        "wd0-nodecay-lr0.04-tv3": [*RULE_LEGO, *tv_weights(3.0)],
        "wd0-nodecay-lr0.04-tv4": LEGO_TV4,
        "wd0-nodecay-lr0.04-tv6": [*RULE_LEGO, *tv_weights(6.0)],
        "wd0-nodecay-lr0.04-tv8": [*RULE_LEGO, *tv_weights(8.0)],
        # The raw factors start inside the f0 band (no initial noise waiting outside it).
        "wd0-nodecay-lr0.04-inband": [*RULE_LEGO, *IN_BAND],
        "wd0-nodecay-lr0.04-ramp0.5-inband": [*RULE_LEGO, RAMP, "0.5", *IN_BAND],
        "wd0-nodecay-lr0.04-tv2-inband": [*RULE_LEGO, *tv_weights(2.0), *IN_BAND],
        # Session 20: RegNeRF's depth smoothness on patches from poses between the four cameras, on the rule.
        "wd0-nodecay-lr0.04-tv4-ds1": [*LEGO_TV4, *depth_smoothness(1.0)],
        # Session 25: the curriculum's own levers again, now on the object rule's TV 4 (tried at TV 1 before).
        "wd0-nodecay-lr0.04-tv4-ramp0.1": [*LEGO_TV4, RAMP, "0.1"],
        "wd0-nodecay-lr0.04-tv4-ramp0.5": [*LEGO_TV4, RAMP, "0.5"],
        "wd0-nodecay-lr0.04-tv4-ffinal0.85": [*LEGO_TV4, F_FINAL, "0.85"],
        "wd0-nodecay-lr0.04-tv4-f0.1": [*LEGO_TV4, *first_band("0.1")],
        "wd0-nodecay-lr0.04-tv4-f0.5": [*LEGO_TV4, *first_band("0.5")],
        "wd0-nodecay-lr0.06-tv4": [*WD0, *NO_DECAY, "--optimizer.lr-grids", "0.06", *tv_weights(4.0)],
        "wd0-nodecay-lr0.04-tv4-f0.05": [*LEGO_TV4, *first_band("0.05")],
        "wd0-nodecay-lr0.04-tv4-f0d0.1": [*LEGO_TV4, F0_DENSITY, "0.1"],
        "wd0-nodecay-lr0.04-tv4-f0.1-ffinal0.85": [
            *LEGO_TV4, *first_band("0.1"), F_FINAL, "0.85"],
        # Session 26: levers outside the curriculum, for both methods: a random background behind the object's alpha
        # (white floaters can no longer hide against the white), and half TensoRF's component counts.
        "wd0-nodecay-lr0.04-tv4-bgrand": [*LEGO_TV4, *RANDOM_BACKGROUND],
        # Session 29: the "holes" of f0 0.05 at 1500 iterations are opaque density outside the object's silhouette
        # (13 val views: 3435 pixels opaque over the background against the rule's 1849; missing 179 against 188),
        # which a white background cannot reject: a random background. It lifted f0 0.05 at 1500 from 21.56 to 23.28
        # (seed 20211202) but emptied the field in the comp8 run at 800 (9.60) and in the P-MID run (train PSNR 12.7
        # at step 1500, stopped), as it did tensorf-vm's (9.6 above): not usable without a guard.
        "wd0-nodecay-lr0.04-tv4-f0.05-bgrand": [*LEGO_TV4, *first_band("0.05"), *RANDOM_BACKGROUND],
        "wd0-nodecay-lr0.04-tv4-comp8-f0.05-bgrand": [
            *LEGO_COMP8, *first_band("0.05"), *RANDOM_BACKGROUND,
        ],
        "wd0-nodecay-lr0.04-tv4-comp8": [*LEGO_COMP8],
        "wd0-nodecay-lr0.04-tv6-comp8": [*RULE_LEGO, *tv_weights(6.0), *components(8, 24)],
        "wd0-nodecay-lr0.04-tv4-comp4": [*LEGO_TV4, *components(4, 12)],
        "wd0-nodecay-lr0.04-tv4-comp8-f0.1": [*LEGO_COMP8, *first_band("0.1")],
        "wd0-nodecay-lr0.04-tv4-comp8-f0.05": [*LEGO_COMP8, *first_band("0.05")],
        # Session 26: a band that stops short of the whole spectrum at P-MID, where 2400 iterations follow the ramp.
        "wd0-nodecay-lr0.04-tv4-ffinald0.7": [*LEGO_TV4, F_FINAL, "0.7", F_FINAL_COLOR, "1.0"],
        # Session 27: the final grid from step 8 (one upsample at 1 % of the run) instead of TensoRF's 64³ -> 128³ over
        # two upsamples: the band's opening is then the only coarse-to-fine schedule, where a bare TensoRF overfits.
        "wd0-nodecay-lr0.04-tv4-comp8-up0.01": [*LEGO_COMP8, *EARLY_FINAL_GRID],
        "wd0-nodecay-lr0.04-tv4-comp8-f0.05-up0.01": [
            *LEGO_COMP8, *first_band("0.05"), *EARLY_FINAL_GRID],
        "wd0-nodecay-lr0.04-tv4-comp8-f0.05-ramp0.5-up0.01": [
            *LEGO_COMP8, *first_band("0.05"), RAMP, "0.5", *EARLY_FINAL_GRID],
        # Session 27: P-CPU's val choice lost 0.8 dB at 1500 iterations; does the initial noise waiting outside its
        # narrow first band (weight decay 0 keeps it) explain it?
        "wd0-nodecay-lr0.04-tv4-comp8-f0.05-inband": [*LEGO_COMP8, *first_band("0.05"), *IN_BAND],
        # Session 29: mirror boundaries (nothing wraps across the box's faces while the band is narrow), on the rule
        # and with the narrow first band.
        "wd0-nodecay-lr0.04-tv4-comp8-mirror": [*LEGO_COMP8, *MIRROR],
        "wd0-nodecay-lr0.04-tv4-comp8-f0.05-mirror": [*LEGO_COMP8, *first_band("0.05"), *MIRROR],
        # Session 27: the narrow first band's renders at 1500 show holes in the body: is it the occupancy grid's first
        # update (20 % of the run, the step the band opens fully) pruning cells the band-limited field has not filled?
        "wd0-nodecay-lr0.04-tv4-f0.05-alphamask0.3": [*LEGO_TV4, *first_band("0.05"), *LATE_ALPHA_MASK],
        "wd0-nodecay-lr0.04-tv4-alphamask0.3": [*LEGO_TV4, *LATE_ALPHA_MASK],
        # Session 28: the regime the paper says the curriculum is for, a grid finer than the images need (P-CPU's
        # 100x100 views on 96³ -> 192³ and 128³ -> 256³ instead of 64³ -> 128³), where TensoRF should overfit first.
        # Session 30: why a random background empties a field (comp8 at 800, tensorf-vm at seed 20211202): the field
        # never lit (train PSNR 13 from step 50, density L1 down 20x by step 50). Is it the density L1 winning over
        # the weaker, noisier pull of object pixels on a random background?
        "wd0-nodecay-lr0.04-tv4-bgrand-l1off": [*LEGO_TV4, *RANDOM_BACKGROUND, *L1_OFF],
        "wd0-nodecay-lr0.04-tv4-comp8-f0.05-bgrand-l1off": [
            *LEGO_COMP8, *first_band("0.05"), *RANDOM_BACKGROUND, *L1_OFF],
        # It is (both lit and ended at 21.64 and 23.19 without it). Which part helps: the L1's absence or the random
        # background, and does the L1 once the field has lit (from the first occupancy update) empty it again?
        "wd0-nodecay-lr0.04-tv4-comp8-l1off": [*LEGO_COMP8, *L1_OFF],
        "wd0-nodecay-lr0.04-tv4-comp8-f0.05-l1off": [*LEGO_COMP8, *first_band("0.05"), *L1_OFF],
        "wd0-nodecay-lr0.04-tv4-comp8-bgrand-l1off": [*LEGO_COMP8, *RANDOM_BACKGROUND, *L1_OFF],
        "wd0-nodecay-lr0.04-tv4-comp8-f0.05-bgrand-l1late": [
            *LEGO_COMP8, *first_band("0.05"), *RANDOM_BACKGROUND, *L1_LATE],
        "wd0-nodecay-lr0.04-tv4-comp8-f0.03-bgrand-l1off": [
            *LEGO_COMP8, *first_band("0.03"), *RANDOM_BACKGROUND, *L1_OFF],
        "wd0-nodecay-lr0.04-tv4-f0.05-bgrand-l1off": [*LEGO_TV4, *first_band("0.05"), *RANDOM_BACKGROUND, *L1_OFF],
        # Session 30: both random-background runs at P-MID (no L1: val 20.99; L1 from the first occupancy update:
        # 21.71, against the rule's 22.50) kept the fog a fresh field starts with wherever no training ray crosses the
        # background: the occupancy box did not shrink (2.5 x 3.0 x 2.2 against 1.5 x 2.6 x 1.8) and coloured floaters
        # showed at its edges. So the random background now starts after the first occupancy update (white and
        # TensoRF's L1 before it): the field lights, the L1 clears the fog, the box shrinks.
        "wd0-nodecay-lr0.04-tv4-bgwarm": [*LEGO_TV4, *RANDOM_AFTER_UPDATE],
        "wd0-nodecay-lr0.04-tv4-comp8-bgwarm": [*LEGO_BGWARM],
        # Session 45: the density curriculum on x and y only (fern's image plane; on lego z is up, not depth).
        "wd0-nodecay-lr0.04-tv4-comp8-bgwarm-zfree": [*LEGO_BGWARM, *DENSITY_XY],
        # Session 46: the colour's first band alone: open from the first step (the curriculum on the geometry only), or
        # narrower than the density's 0.3.
        **{
            f"wd0-nodecay-lr0.04-tv4-comp8-bgwarm-f0c{name}": [
                *LEGO_BGWARM, F0_COLOR, f0,
            ]
            for name, f0 in (("1", "1.0"), ("0.1", "0.1"), ("0.05", "0.05"))
        },
        # ... and the colour band held below the spectrum to the end (the geometry's opens fully).
        **{
            f"wd0-nodecay-lr0.04-tv4-comp8-bgwarm-ffinalc{f}": [
                *LEGO_BGWARM, F_FINAL_COLOR, f,
            ]
            for f in ("0.7", "0.5")
        },
        "wd0-nodecay-lr0.04-tv4-comp8-f0.05-bgwarm": [
            *LEGO_COMP8, *first_band("0.05"), *RANDOM_AFTER_UPDATE],
        # Session 47: mip-NeRF 360's distortion loss on each method's val choice: fourierf-vm 23.17 at 0.01 and 22.16
        # at 0.1 against 23.18.
        **{
            f"wd0-nodecay-lr0.04-tv4-comp8-f0.05-bgwarm-dist{w}": [
                *LEGO_COMP8, *first_band("0.05"), *RANDOM_AFTER_UPDATE, *distortion(w),
            ]
            for w in ("0.001", "0.01", "0.1")
        },
        **{
            f"wd0-nodecay-lr0.04-tv4-comp8-bgwarm-dist{w}": [
                *LEGO_BGWARM, *distortion(w),
            ]
            for w in ("0.001", "0.01", "0.1")
        },
        # Session 59: InfoNeRF's ray entropy on each method's val choice. Session 61: the second group's 0.00003 on
        # fourierf-vm too (the object rule's own settings, which then took the entropy for objects). Session 62: both
        # groups' 0.00003 at 1040 and 1500 iterations (``pcpu1040``, ``pcpu1500``), where the first band of 0.05 lost,
        # so the object rule takes it at 800 iterations only.
        **{
            f"wd0-nodecay-lr0.04-tv4-comp8-f0.05-bgwarm-ent{w}": [
                *LEGO_COMP8, *first_band("0.05"), *RANDOM_AFTER_UPDATE, *entropy(w),
            ]
            for w in ("0.00001", "0.00003", "0.0001", "0.0003", "0.001")
        },
        **{
            f"wd0-nodecay-lr0.04-tv4-comp8-bgwarm-ent{w}": [
                *LEGO_BGWARM, *entropy(w),
            ]
            for w in ("0.00001", "0.00003", "0.0001", "0.0003", "0.001")
        },
        # Session 63: the narrow first band's neighbours at 800 iterations on the rule with the entropy (0.05 won
        # there by 0.23 val over the paper's 0.3): a narrower or wider band, the band open sooner or later, the
        # geometry's band narrow and the colour's at the paper's 0.3.
        **{
            f"wd0-nodecay-lr0.04-tv4-comp8-f{f0}-bgwarm-ent0.00003": [
                *LEGO_COMP8, *first_band(f0), *RANDOM_AFTER_UPDATE, *entropy("0.00003"),
            ]
            for f0 in ("0.02", "0.1")
        },
        **{
            f"wd0-nodecay-lr0.04-tv4-comp8-f0.05-ramp{r}-bgwarm-ent0.00003": [
                *LEGO_COMP8, *first_band("0.05"), RAMP, r, *RANDOM_AFTER_UPDATE, *entropy("0.00003"),
            ]
            for r in ("0.1", "0.3")
        },
        "wd0-nodecay-lr0.04-tv4-comp8-f0d0.05-bgwarm-ent0.00003": [
            *LEGO_COMP8, F0_DENSITY, "0.05", *RANDOM_AFTER_UPDATE, *entropy("0.00003"),
        ],
        # ... and the TV weight on the narrow band (the curriculum is a smoothness prior too: does it want less?).
        **{
            f"wd0-nodecay-lr0.04-tv{tv}-comp8-f0.05-bgwarm-ent0.00003": [
                *RULE_LEGO, *tv_weights(float(tv)), *components(8, 24), *first_band("0.05"), *RANDOM_AFTER_UPDATE,
                *entropy("0.00003"),
            ]
            for tv in (2, 3, 6)
        },
        # Session 64: TV 6 on the narrow band led seed 20211202 (23.48 against TV 4's 23.33), so tensorf-vm's rule at
        # TV 6 and 8 with the entropy too: one TV for both methods, or none moves.
        **{
            f"wd0-nodecay-lr0.04-tv{tv}-comp8-bgwarm-ent0.00003": [
                *RULE_LEGO, *tv_weights(float(tv)), *components(8, 24), *RANDOM_AFTER_UPDATE, *entropy("0.00003"),
            ]
            for tv in (6, 8)
        },
        # Session 60: how many unseen rays the entropy at 0.00003 scores (1024 above, InfoNeRF's; 0 = training rays
        # only), on each method's P-CPU val choice.
        **{
            f"wd0-nodecay-lr0.04-tv4-comp8-f0.05-bgwarm-ent0.00003-u{n}": [
                *LEGO_COMP8, *first_band("0.05"), *RANDOM_AFTER_UPDATE, *entropy("0.00003", n),
            ]
            for n in (0, 256, 4096)
        },
        **{
            f"wd0-nodecay-lr0.04-tv4-comp8-bgwarm-ent0.00003-u{n}": [*LEGO_BGWARM, *entropy("0.00003", n)]
            for n in (0, 256, 4096)
        },
        "wd0-nodecay-lr0.04-tv6-bgwarm": [*RULE_LEGO, *tv_weights(6.0), *RANDOM_AFTER_UPDATE],
        # Session 60: the entropy at P-CPU's val-chosen weight on tensorf-vm's P-MID choice (fourierf-vm's P-MID choice
        # with it is above).
        "wd0-nodecay-lr0.04-tv6-bgwarm-ent0.00003": [
            *RULE_LEGO, *tv_weights(6.0), *RANDOM_AFTER_UPDATE, *entropy("0.00003")],
        # Session 32: TensoRF's TV need at P-HIGH's image and grid (TV 6 won at P-MID's, TV 4 at P-CPU's).
        # Session 33: TV 14, past TV 10 where TensoRF's val still rose, on the same 300³ grid (pmid300). Session 35:
        # TV 12 at P-HIGH (its val rose to TV 10 there), with fourierf-vm's TV 8 below, so both searches are two-sided.
        # Session 38: TV 14 at P-HIGH on three seeds (TV 12, the three-seed choice, was the top); it won (22.10).
        # Session 39: TV 16, as TV 14 was again the top tried and TensoRF's three-seed val still rose; it lost on both
        # seeds it ran (21.07, 21.83 against TV 14's 21.33, 22.57), so TV 14 is the peak.
        **{
            f"wd0-nodecay-lr0.04-tv{tv}-bgwarm": [*RULE_LEGO, *tv_weights(float(tv)), *RANDOM_AFTER_UPDATE]
            for tv in (8, 10, 12, 14, 16)
        },
        # fourierf-vm TV steps above its TV 4 (its val choice at every size up to P-MID), on the 300³ grid; session 34:
        # TV 8 and tensorf-vm's TV 12, as TV 6 (fourierf-vm's best) was the top of its tried range; TV 10 and 12, as
        # TV 8 (val 23.03 over three seeds, TV 6 22.83) was again the top. Session 40: tensorf-vm's P-HIGH choice
        # (TV 14) on the object rule's half components, which its P-HIGH search had left at TensoRF's 16 / 48 while
        # fourierf-vm's ran on 8 / 24 (and fourierf-vm's TV 12 on 16 / 48 above): seed 20211202 val 22.59 against
        # 21.33 on 16 / 48 (fourierf-vm 22.57 against 22.45). Session 42: TV 16, so tensorf-vm's P-HIGH search on 8 / 24
        # can be two-sided (run in session 43, below); on pmid300's first seed TV 10, 12, 14 on 8 / 24 read val
        # 22.53, 22.47, 22.50, and TV 12 over three seeds 22.72 against 22.51 on 16 / 48, tensorf-vm's choice there.
        # Session 43: at P-HIGH on 8 / 24 tensorf-vm's seed 20211202 reads TV 10 22.05, 12 22.70, 14 22.59, 16 22.26,
        # and TV 12 over three seeds 22.51 against TV 14's 22.40, its choice; fourierf-vm's TV 16 (its TV 4-12 flat)
        # read 22.55 against TV 12's 22.45 on that seed, but 22.40 over three seeds against TV 12's 22.44, so TV 12
        # stays fourierf-vm's choice. Session 44: pmid300 tensorf-vm TV 10 and 14 on 8 / 24, seeds 1 and 2 (level with
        # TV 12 on the first seed): val 23.22, 22.85 and 22.64, 22.87, so over three seeds TV 10 (22.87) overtakes TV 12
        # (22.72) and TV 14 (22.67) as its choice, and the gap falls from +0.50 to +0.24 dB test.
        # TV 8 on seeds 20211202 and 1 (val 21.11, 22.99) falls below TV 10 on both, so that search is two-sided.
        **{
            f"wd0-nodecay-lr0.04-tv{tv}-comp8-bgwarm": [
                *RULE_LEGO, *tv_weights(float(tv)), *components(8, 24), *RANDOM_AFTER_UPDATE]
            for tv in (6, 8, 10, 12, 14, 16)
        },
        # tensorf-vm's P-MID choice (TV 6) with the same random background and no L1: does TensoRF, which overfits
        # more at P-MID, gain from it there (it lost at P-CPU: 22.80 -> 22.13)?
        "wd0-nodecay-lr0.04-tv6-bgrand-l1off": [*RULE_LEGO, *tv_weights(6.0), *RANDOM_BACKGROUND, *L1_OFF],
        **{
            f"wd0-nodecay-lr0.04-tv4-comp8-g{final}": [*LEGO_COMP8, *grid(final // 2, final)]
            for final in (192, 256)
        },
    },
    # Forward-facing scenes: the real-scene preset (the trainer applies it), its grid lr, the occlusion term, f0/Δ,
    # Floaters-No-More gradient scaling.
    "fern": {
        "preset": [],
        "lr0.04": ["--optimizer.lr-grids", "0.04"],
        "lr0.08": ["--optimizer.lr-grids", "0.08"],
        "lr0.08-tvconst": ["--optimizer.lr-grids", "0.08", *TV_CONST],
        "lr0.08-occ0.1": ["--optimizer.lr-grids", "0.08", *occlusion("0.1")],
        "lr0.08-occ0": ["--optimizer.lr-grids", "0.08", *occlusion("0")],
        "lr0.08-ramp0.5": ["--optimizer.lr-grids", "0.08", "--pipeline.model.fourier.ramp-fraction", "0.5"],
        "lr0.08-ramp0.25": ["--optimizer.lr-grids", "0.08", RAMP, "0.25"],
        "lr0.08-fnm": ["--optimizer.lr-grids", "0.08", *FNM],
        "lr0.08-tvconst-fnm": ["--optimizer.lr-grids", "0.08", *TV_CONST, *FNM],
        "lr0.08-tvconst-ramp0.5": ["--optimizer.lr-grids", "0.08", *TV_CONST, RAMP, "0.5"],
        "lr0.08-tvconst-ffinal0.7": ["--optimizer.lr-grids", "0.08", *TV_CONST, F_FINAL, "0.7"],
        # Session 13: with Floaters-No-More keeping density off the cameras, does a shorter band limit pay?
        "lr0.08-tvconst-fnm-ramp0.5": ["--optimizer.lr-grids", "0.08", *TV_CONST, *FNM, RAMP, "0.5"],
        "lr0.08-tvconst-fnm-ramp0.25": ["--optimizer.lr-grids", "0.08", *TV_CONST, *FNM, RAMP, "0.25"],
        # Session 14: at 3000 iterations the band opens only at the end; a quarter of the run opens it by step 750.
        "lr0.08-tvconst-ramp0.25": ["--optimizer.lr-grids", "0.08", *TV_CONST, RAMP, "0.25"],
        # Session 16: TV 4 won on lego for both methods; does a stronger TV term carry to a forward-facing scene?
        "lr0.08-tvconst-tv2": ["--optimizer.lr-grids", "0.08", *TV_CONST, *tv_weights(2.0)],
        "lr0.08-tvconst-tv4": FERN_TV4,
        # Session 17: the forward-facing rule at 3000 iterations (band open by step 800: 800 / 3000).
        "lr0.08-tvconst-ramp0.2667": ["--optimizer.lr-grids", "0.08", *TV_CONST, RAMP, "0.2667"],
        "lr0.08-tvconst-ramp0.2667-tv4": FERN_PMID_RULE,
        # Session 18: Floaters-No-More (tensorf-vm's val choice at 800 iterations, TV 1) on top of TV 4.
        "lr0.08-tvconst-tv4-fnm": [*FERN_TV4, *FNM],
        # Session 19: the same for fourierf-vm at 3000 iterations, with the rule's ramp (band open by step 800).
        "lr0.08-tvconst-ramp0.2667-tv4-fnm": [*FERN_PMID_RULE, *FNM],
        # Session 20: RegNeRF's depth smoothness on 8×8 patches from poses between the training cameras, on the rule.
        **{
            f"lr0.08-tvconst-tv4-ds{weight}": [*FERN_TV4, *depth_smoothness(weight)] for weight in (0.1, 1, 10)
        },
        # Session 23: around the P-MID choice on seeds 1 and 2 (one GPU call): a stronger TV, a band open by step 450.
        "lr0.08-tvconst-ramp0.2667-tv6": fern_rule("0.2667", tv=6.0),
        "lr0.08-tvconst-ramp0.15-tv4": fern_rule("0.15"),
        # Session 23: the choice under the two other ReLU rules (dead_start.py): revive every dark batch, TensoRF's.
        "lr0.08-tvconst-ramp0.2667-tv4-revive1": [*FERN_PMID_RULE, *REVIVE1],
        # Session 45: the density curriculum on the image plane only (``DENSITY_XY``), on the rule's settings at
        # 3000 and 1500 iterations.
        "lr0.08-tvconst-ramp0.2667-tv4-revive1-zfree": [*FERN_PMID_RULE, *REVIVE1, *DENSITY_XY],
        # (Session 47, a throwaway prototype not kept: z's band at the square root of the cutoff, between every axis
        # and z unfiltered, read 20.11 at 800 iterations against 20.51, and 21.36 / 20.87 / 19.91 at 3000 against the
        # rule's 21.19 / 20.71 / 21.02.)
        "lr0.08-tvconst-ramp0.5333-tv4-revive1-zfree": [*fern_rule("0.5333"), *REVIVE1, *DENSITY_XY],
        "lr0.08-tvconst-ramp0.2667-tv4-plain": [*FERN_PMID_RULE, *PLAIN_RELU],
        # Session 24: Floaters-No-More once the band is open (step 800), when the field trains like TensoRF's, which it
        # helps; against the whole run.
        "lr0.08-tvconst-ramp0.2667-tv4-revive1-fnm": [*FERN_PMID_RULE, *REVIVE1, *FNM],
        "lr0.08-tvconst-ramp0.2667-tv4-revive1-fnmlate": [*FERN_PMID_RULE, *REVIVE1, *FNM, FNM_FROM, "0.2667"],
        # Session 24: a band that stops short of the whole spectrum, so the field cannot drift to TensoRF's solution
        # over the 2200 iterations after the ramp: both grids at 0.85, or the geometry alone at 0.7.
        "lr0.08-tvconst-ramp0.2667-tv4-revive1-ffinal0.85": [*FERN_PMID_RULE, *REVIVE1, F_FINAL, "0.85"],
        "lr0.08-tvconst-ramp0.2667-tv4-revive1-ffinald0.7": [
            *FERN_PMID_RULE, *REVIVE1, F_FINAL, "0.7", F_FINAL_COLOR, "1.0",
        ],
        # Session 24: a wider first band (the real preset's f0 is 0.01: little more than the mean), and half the grid lr
        # for the longer run.
        "lr0.08-tvconst-ramp0.2667-tv4-revive1-f0.05": [
            *FERN_PMID_RULE, *REVIVE1, *first_band("0.05"),
        ],
        "lr0.04-tvconst-ramp0.2667-tv4-revive1": [*fern_rule("0.2667", lr="0.04"), *REVIVE1],
        # Session 24: the budget rule at 1500 iterations (band open by step 800), waiting for a fresh field or reviving
        # at once, for both methods.
        "lr0.08-tvconst-ramp0.5333-tv4": fern_rule("0.5333"),
        "lr0.08-tvconst-ramp0.5333-tv4-revive1": [*fern_rule("0.5333"), *REVIVE1],
        "lr0.08-tvconst-tv4-revive1": [*FERN_TV4, *REVIVE1],
        # Session 46: the short-run rule's TV 6 at 1500 iterations, for both methods (its boundary is 800).
        "lr0.08-tvconst-ramp0.5333-tv6-revive1": [*fern_rule("0.5333", tv=6.0), *REVIVE1],
        "lr0.08-tvconst-tv6-revive1": [*fern_tv(6), *REVIVE1],
        # ... and at 3000 iterations the band open by step 1500 instead of 800.
        "lr0.08-tvconst-ramp0.5-tv4-revive1": [*fern_rule("0.5"), *REVIVE1],
        # Session 26: half TensoRF's component counts (lego's object rule gained 0.14 dB over 3 seeds at P-CPU) on
        # fourierf-vm's P-CPU choice.
        "lr0.08-tvconst-tv4-comp8": [*FERN_TV4, *components(8, 24)],
        # Session 28: Floaters-No-More lifts tensorf-vm past fourierf-vm (P-CPU val 20.69 against 20.05) but not
        # fourierf-vm, whose narrow band holds the near leaves back while FNM slows them too: FNM with a band that
        # opens early (by 5-25 % of the run) or starts wider.
        **{f"lr0.08-tvconst-tv4-fnm-ramp{r}": [*FERN_TV4, *FNM, RAMP, r] for r in ("0.05", "0.1", "0.25")},
        "lr0.08-tvconst-tv4-fnm-f0.3-ramp0.1": [*FERN_TV4, *FNM, *first_band("0.3"), RAMP, "0.1"],
        # Session 28: seeds 1 and 2 of fnm-ramp0.1 stalled at train PSNR ~17 with 19 % and 33 % of the occupancy grid
        # kept (69 % on seed 20211202): is it the single occupancy update at 10 % (step 80) pruning a field not yet lit?
        "lr0.08-tvconst-tv4-fnm-ramp0.1-alphamask0.25": [*FERN_TV4, *FNM, RAMP, "0.1", *OCCUPANCY_AT_STEP_200],
        # ... and the same later update on each method's P-CPU choice: what does it cost where the update at step 80
        # did not prune a dim field? (The budget rule's since session 28.)
        "lr0.08-tvconst-tv4-alphamask0.25": [*fern_short(4.0)],
        "lr0.08-tvconst-tv4-fnm-alphamask0.25": [*FERN_TV4, *FNM, *OCCUPANCY_AT_STEP_200],
        # Session 29: the filters' periodic wrap puts NDC's far wall (z = 1) onto the near plane (z = -1) while the
        # band is narrow; fourierf-vm shows a near blob tensorf-vm lacks (the hanging frond, as it turned out): mirror
        # boundaries instead, with and
        # without Floaters-No-More.
        "lr0.08-tvconst-tv4-alphamask0.25-mirror": [*fern_short(4.0), *MIRROR],
        "lr0.08-tvconst-tv4-fnm-alphamask0.25-mirror": [*FERN_TV4, *FNM, *OCCUPANCY_AT_STEP_200, *MIRROR],
        # Session 29: a band open by step 80 still cost ~1 dB beside FNM (fnm-ramp0.1 above; FNM on density growth
        # alone collapsed every run to ~16 dB, not kept): FNM from the step the band is open, as the paper applies
        # FNM to TensoRF.
        **{
            f"lr0.08-tvconst-tv4-fnm-ramp{r}-fnmfrom{r}-alphamask0.25": [
                *FERN_TV4, *FNM, RAMP, r, FNM_FROM, r, *OCCUPANCY_AT_STEP_200,
            ]
            for r in ("0.1", "0.25")
        },
        # Session 29: fourierf-vm's fern renders are softer than tensorf-vm's with Floaters-No-More: the curriculum on
        # the geometry alone (the appearance grids unfiltered from step 0), with and without FNM.
        "lr0.08-tvconst-tv4-alphamask0.25-f0c1": [*fern_short(4.0), F0_COLOR, "1.0"],
        "lr0.08-tvconst-tv4-fnm-alphamask0.25-f0c1": [*FERN_TV4, *FNM, *OCCUPANCY_AT_STEP_200, F0_COLOR, "1.0"],
        # Session 45: fourierf-vm's fern fits are soft in depth, where three views pin a surface down and the band
        # holds it back: the density curriculum on the image plane only (x and y; NDC depth z unfiltered), with and
        # without FNM. (A throwaway prototype that held z's band narrower than x's and y's lost: half the cutoff
        # 19.64, the cutoff squared 19.89, against 20.08 on seed 20211202.)
        "lr0.08-tvconst-tv4-alphamask0.25-zfree": [*fern_short(4.0), *DENSITY_XY],
        "lr0.08-tvconst-tv4-fnm-alphamask0.25-zfree": [*FERN_TV4, *FNM, *OCCUPANCY_AT_STEP_200, *DENSITY_XY],
        # ... and on it the levers its new field may want otherwise: mirror boundaries (x and y only now wrap), and
        # the TV weight chosen without it (4) a step or two either way.
        "lr0.08-tvconst-tv4-alphamask0.25-zfree-mirror": [*fern_short(4.0), *DENSITY_XY, *MIRROR],
        **{
            f"lr0.08-tvconst-tv{tv}-alphamask0.25-zfree": fern_image_plane(tv)
            for tv in (2, 6, 8)
        },
        # ... and, since fourierf-vm's best val mean moved to TV 6 there, tensorf-vm's val choice (TV 4 with FNM) at
        # TV 6 as well, so neither method's TV search stops a step short of the other's.
        "lr0.08-tvconst-tv6-fnm-alphamask0.25": [*fern_tv(6), *FNM, *OCCUPANCY_AT_STEP_200],
        # ... and plain tensorf-vm, the rule's other method, at the rule's TV 4 and at TV 6 (its share of a TV rule).
        "lr0.08-tvconst-tv6-alphamask0.25": [*fern_short(6)],
        # Session 46: on the image-plane curriculum at TV 6, the band's start and speed searched again (the preset's
        # f0 0.01 and whole-run ramp were chosen with every axis filtered), the grid lr and depth smoothness, and the
        # density band open from the start (appearance curriculum only). (Throwaway prototypes, not kept, filtered the
        # appearance on x and y only, 18.72, or on z only, 19.75, or held its z band at the cutoff squared, 20.35, or
        # cubed, 20.07, against 20.51.)
        **{
            f"lr0.08-tvconst-tv6-alphamask0.25-zfree-f0d{f0}": [
                *fern_image_plane(6), F0_DENSITY, f0,
            ]
            for f0 in ("0.05", "0.1")
        },
        "lr0.08-tvconst-tv6-alphamask0.25-zfree-ramp0.75": [
            *fern_image_plane(6), RAMP, "0.75",
        ],
        "lr0.08-tvconst-tv6-alphamask0.25-f0d1": [*fern_short(6), F0_DENSITY, "1.0"],
        # ... and Floaters-No-More, tensorf-vm's lever, which with every axis filtered did nothing for fourierf-vm and
        # with z unfiltered at TV 4 fell to 17.78: from the first step, and from step 400 on.
        "lr0.08-tvconst-tv6-fnm-alphamask0.25-zfree": [*fern_image_plane(6), *FNM],
        "lr0.08-tvconst-tv6-fnm-fnmfrom0.5-alphamask0.25-zfree": [
            *fern_image_plane(6), *FNM, FNM_FROM, "0.5",
        ],
        "lr0.12-tvconst-tv6-alphamask0.25-zfree": [
            *fern_image_plane(6, lr="0.12"),
        ],
        "lr0.08-tvconst-tv6-alphamask0.25-zfree-ds1": [
            *fern_image_plane(6), *depth_smoothness(1.0),
        ],
        # Session 47: mip-NeRF 360's distortion loss (one short interval of weight per ray), against the ghosting and
        # doubled geometry, on each method's rule and on tensorf-vm's val choice (FNM). fourierf-vm fell at every
        # weight (20.51 -> 19.97, 19.22, 16.01), tensorf-vm with FNM tied at 0.001 (20.70 -> 20.67).
        **{
            f"lr0.08-tvconst-tv6-alphamask0.25-zfree-dist{w}": [*fern_image_plane(6), *distortion(w)]
            for w in ("0.001", "0.01", "0.1")
        },
        **{
            f"lr0.08-tvconst-tv6-alphamask0.25-dist{w}": [*fern_short(6), *distortion(w)]
            for w in ("0.001", "0.01", "0.1")
        },
        **{
            f"lr0.08-tvconst-tv4-fnm-dist{w}": [*FERN_TV4, *FNM, *distortion(w)]
            for w in ("0.001", "0.01", "0.1")
        },
        # Session 59: InfoNeRF's ray entropy on each method's P-CPU val choice, against the same ghosting.
        **{
            f"lr0.08-tvconst-tv6-alphamask0.25-zfree-ent{w}": [*fern_image_plane(6), *entropy(w)]
            for w in ("0.00003", "0.0001", "0.001")
        },
        **{
            f"lr0.08-tvconst-tv6-fnm-alphamask0.25-ent{w}": [*fern_tv(6), *FNM, *OCCUPANCY_AT_STEP_200, *entropy(w)]
            for w in ("0.00003", "0.0001", "0.001")
        },
        # ... and tensorf-vm's val choice under TensoRF's plain ReLU: its recorded rows (commit 71362f1) predate the
        # reviving ReLU, and a rerun under the current default read val 20.14 against the recorded 20.70. Plain reads
        # 20.14 too, so the revival is not what moved it; the thread count is (the docstring; docs/few-shot-quality.md).
        "lr0.08-tvconst-tv4-fnm-plain": [*FERN_TV4, *FNM, *PLAIN_RELU],
        # ... and FreeNeRF's occlusion weight (0.01, the preset's) off, tripled and tenfold on the image-plane rule:
        # 20.22, 20.59, 20.48 against 20.51; 0.03 on seed 1 19.54 against 19.86, so 0.01 stays.
        **{
            f"lr0.08-tvconst-tv6-alphamask0.25-zfree-occ{w}": [
                *fern_image_plane(6), *occlusion(w),
            ]
            for w in ("0", "0.03", "0.1")
        },
    },
}  # fmt: skip
CURRICULUM_ONLY = ("ramp", "f0", "ffinal", "inband", "mirror", "zfree")
"""Settings that only change the curriculum: tensorf-vm (masks off) would repeat its run, so it skips them."""


def applies(method: str, setting: str) -> bool:
    return method != "tensorf-vm" or not any(part.startswith(CURRICULUM_ONLY) for part in setting.split("-"))


def parser_args(scene: str, protocol: Protocol) -> list[str]:
    if scene == "lego":
        return ["blender-data", "--downscale", str(protocol.lego_downscale), "--test-every", "8",
                "--view-ids", "27", "76", "97", "99"]  # fmt: skip
    return ["llff-data", "--num-views", "3"]


def label(protocol: str, setting: str) -> str:
    return f"{protocol}-{setting}"


def execute(run: Run, scene: str, args: argparse.Namespace) -> dict:
    protocol_name, setting = run.views.split("-", 1)
    protocol = PROTOCOLS[protocol_name]
    # --budget-rule False: each run has exactly its setting's values, not the short-run rule's (method_configs.budget)
    extra = [*protocol.flags(), "--device", args.device, "--budget-rule", "False", *SETTINGS[scene][setting]]
    if args.stage == "curve":  # keep a checkpoint every CURVE_EVERY iterations (the later flag wins)
        extra += ["--steps-per-save", str(CURVE_EVERY), "--keep-checkpoints", str(run.iters // CURVE_EVERY + 1)]
    data = args.data / ("blender/lego" if scene == "lego" else "llff/fern")
    lpips, work = args.lpips, args.work / scene
    row = train_and_eval(run, data, parser_args(scene, protocol), work, lpips, scene, extra, args.threads)
    row |= evaluate(Path(row["run_dir"]), run.key, work, lpips, split="val", threads=args.threads)
    if args.stage == "curve":
        row["curve"] = [
            *curve_points(Path(row["run_dir"]), run, work, lpips, args.threads),
            [run.iters, row["val_psnr"], row["psnr"]],
        ]
    return row | {"scene": scene, "protocol": protocol_name, "setting": setting, "device": args.device}


def curve_points(run_dir: Path, run: Run, work: Path, lpips: Path, threads: int | None) -> list[list[float]]:
    """[step, val PSNR, test PSNR] of every checkpoint before the last (the row itself holds the last)."""
    points = []
    for ckpt in sorted((run_dir / "checkpoints").glob("step-*.ckpt")):
        step = int(ckpt.stem.split("-")[-1])
        if step >= run.iters:
            continue
        key = f"{run.key}.step{step}"
        val = evaluate(run_dir, key, work, lpips, split="val", checkpoint=ckpt, threads=threads)["val_psnr"]
        points.append([step, val, evaluate(run_dir, key, work, lpips, checkpoint=ckpt, threads=threads)["psnr"]])
    return points


def run_all(plan: Sequence[tuple[str, Run]], args: argparse.Namespace) -> None:
    """Run what is not yet recorded, ``--jobs`` at a time; each finished row is appended at once."""
    path = args.results
    done = {} if args.again else load_results(path)
    todo = [(scene, run) for scene, run in plan if f"{scene}/{run.key}" not in done]
    todo.sort(key=lambda item: (-item[1].iters, item[0] != "fern"))  # longest first: the pool ends on short runs
    lock = threading.Lock()

    def one(item: tuple[str, Run]) -> None:
        scene, run = item
        try:
            row = execute(run, scene, args)
        except RuntimeError as err:  # the log's end says why; the other runs go on
            logs = sorted((args.work / scene).glob(f"{run.key}*.log"))
            tail = "\n".join(logs[-1].read_text().splitlines()[-15:]) if logs else ""
            print(f"FAILED {scene}/{run.key}: {err}\n{tail}", flush=True)
            return
        row["key"] = f"{scene}/{run.key}"
        with lock:
            record(path, row, args.again)
        print(f"{row['key']}: val {row['val_psnr']:.2f}  train {row['train_seconds']:.0f}s", flush=True)

    print(f"{len(todo)} runs to do ({len(plan) - len(todo)} recorded)", flush=True)
    with ThreadPoolExecutor(max(1, args.jobs)) as pool:
        list(pool.map(one, todo))


def record(path: Path, row: dict, again: str | None = None) -> None:
    """Append a finished row. Run ``--again``, a recorded key's earlier row first moves to ``repeats.jsonl`` with the
    note (the results keep one row a key), so nothing recorded is lost and the report can set the two side by side."""
    held = load_results(path) if again else {}
    earlier = held.pop(row["key"], None)
    if earlier is not None:
        with path.with_name(REPEATS).open("a") as fh:
            fh.write(json.dumps(earlier | {"repeat": again}) + "\n")
        save_results(path, held)
    with path.open("a") as fh:
        fh.write(json.dumps(row) + "\n")


ROW_FIELDS = ("key", "scene", "protocol", "method", "setting", "seed", "val_psnr", "psnr")
"""What the report reads of a row: a row merged from elsewhere must carry each."""


def read_rows(source: Path) -> list[dict]:
    """The rows of a results file written elsewhere (another results path, the device machine), checked for what the
    report reads; ValueError names the file, the line and the fix."""
    if not source.is_file():
        raise ValueError(f"{source}: no such results file; pass the --results path a sweep, seeds or curve stage wrote")
    rows = []
    for number, line in enumerate(source.read_text().splitlines(), start=1):
        if not line.strip():
            continue
        try:
            row = json.loads(line)
        except json.JSONDecodeError as err:
            raise ValueError(f"{source}:{number}: not a JSON row ({err.msg}); one finished run a line") from None
        missing = [f for f in ROW_FIELDS if not isinstance(row, dict) or f not in row]
        if missing:
            raise ValueError(f"{source}:{number}: a row without {', '.join(missing)}; merge only rows pmid.py recorded")
        if row["protocol"] not in PROTOCOLS or row["method"] not in METHODS:
            raise ValueError(f"{source}:{number}: protocol {row['protocol']!r} or method {row['method']!r} is not "
                             f"one of pmid.py's ({', '.join(PROTOCOLS)}; {', '.join(METHODS)})")  # fmt: skip
        rows.append(row)
    return rows


def merge(path: Path, sources: Sequence[Path], again: str | None) -> list[str]:
    """Record the rows of ``sources`` in the results at ``path``, as ``run_all`` records a finished run: a recorded key
    is skipped, or, ``again``, its earlier row moves to the repeats with that note. Every source is read and checked
    before anything is written. Why: runs trained side by side as separate processes (or on the device machine) write
    their own results files, and one process must move rows between the files."""
    if any(source.resolve() == path.resolve() for source in sources):
        raise ValueError(f"{path}: the results cannot be merged into themselves; pass the other run's --results file")
    rows = [row for source in sources for row in read_rows(source)]
    held = load_results(path)
    lines = []
    for row in rows:
        if row["key"] in held and again is None:
            lines.append(f"{row['key']}: recorded, skipped (--again NOTE keeps this row, the earlier to the repeats)")
            continue
        record(path, row, again)
        held[row["key"]] = row
        threads = row.get("train_threads", "?")
        lines.append(f"{row['key']}: val {row['val_psnr']:.2f}  test {row['psnr']:.2f}  (threads {threads})")
    return lines


def rows_by(results: dict[str, dict], scene: str, protocol: str, method: str) -> dict[str, list[dict]]:
    """Recorded rows of one (scene, protocol, method), grouped by setting."""
    out: dict[str, list[dict]] = {}
    for r in results.values():
        if (r["scene"], r["protocol"], r["method"]) == (scene, protocol, method):
            out.setdefault(r["setting"], []).append(r)
    return out


def chosen_setting(groups: dict[str, list[dict]]) -> str | None:
    """The setting with the best mean validation PSNR over ``SEEDS`` among those run on every seed (the seeds stage
    runs the sweep's leaders), else the best validation PSNR of the first seed (the sweep's seed).

    Why the mean where there is one: one seed's val PSNR moves by about 0.15 dB from seed to seed, so the best of
    many single-seed settings is mostly the luckiest (lego P-CPU: four settings within 0.03 dB of each other over
    three seeds spanned 22.37-22.58 on the first)."""
    seeded = {s: vals for s, rows in groups.items() if len(vals := val_by_seed(rows)) == len(SEEDS)}
    if seeded:
        return max(seeded, key=lambda s: float(np.mean(list(seeded[s].values()))))
    first = {s: [r for r in rows if r["seed"] == SEEDS[0]] for s, rows in groups.items()}
    scored = {s: rows[0]["val_psnr"] for s, rows in first.items() if rows}
    return max(scored, key=scored.__getitem__) if scored else None


def val_by_seed(rows: list[dict]) -> dict[int, float]:
    """A setting's val PSNR per seed of ``SEEDS`` that it ran on, in ``SEEDS``' order (one row per seed: the key
    names it)."""
    recorded = {r["seed"]: r["val_psnr"] for r in rows}
    return {seed: recorded[seed] for seed in SEEDS if seed in recorded}


def val_cell(rows: list[dict]) -> str:
    """A setting's val PSNR for the sweep table: the first seed's, and the mean over every seed where all were run,
    else over the seeds that were (named, as such a mean does not take part in the choice)."""
    vals = val_by_seed(rows)
    first = f"{vals[SEEDS[0]]:.2f}" if SEEDS[0] in vals else "—"
    mean = float(np.mean(list(vals.values()))) if vals else 0.0
    if len(vals) == len(SEEDS):
        return f"{first} (seeds: {mean:.2f})"
    if len(vals) > 1:
        return f"{first} (seeds {', '.join(map(str, vals))}: {mean:.2f})"
    return first


def sweep_plan(args: argparse.Namespace) -> list[tuple[str, Run]]:
    return [
        (scene, Run(method, PROTOCOLS[p].iters, SEEDS[0], label(p, setting)))
        for p in args.protocol
        for scene in args.scene
        for setting in SETTINGS[scene]
        for method in args.methods or METHODS
        if applies(method, setting)
        and scene in PROTOCOL_SCENES.get(p, (scene,))
        and (not args.only or setting in args.only)
    ]


def seeds_plan(args: argparse.Namespace) -> list[tuple[str, Run]]:
    results = load_results(args.results)
    seeds = args.seeds or SEEDS[1:]
    plan = []
    for p in args.protocol:
        for scene in args.scene:
            for method in args.methods or METHODS:
                if args.only:  # the seeds of named settings, so that val can choose on more than one seed
                    settings = [s for s in args.only if applies(method, s)]
                else:
                    best = chosen_setting(rows_by(results, scene, p, method))
                    if best is None:
                        sys.exit(f"error: no sweep result for {scene} {p} {method}; run the sweep stage first")
                    settings = [best]
                plan += [
                    (scene, Run(method, PROTOCOLS[p].iters, seed, label(p, s))) for s in settings for seed in seeds
                ]
    return plan


def curve_plan(args: argparse.Namespace) -> list[tuple[str, Run]]:
    """Each method at ``--only``'s settings, else at the val-chosen setting of the 800-iteration protocol of the
    same sizes (``CURVE_BASE``), first seed."""
    results = load_results(args.results)
    plan = []
    for p in args.protocol:
        if p not in CURVE_BASE:
            sys.exit(f"error: the curve stage runs {' or '.join(CURVE_BASE)}, not {p}")
        for scene in args.scene:
            for method in args.methods or METHODS:
                best = chosen_setting(rows_by(results, scene, CURVE_BASE[p], method))
                settings = [s for s in args.only if applies(method, s)] if args.only else [best] if best else []
                if not settings and not args.only:  # --only with curriculum settings alone: tensorf-vm has none
                    sys.exit(
                        f"error: no {CURVE_BASE[p]} sweep result for {scene} {method}; run the sweep or pass --only"
                    )
                plan += [(scene, Run(method, PROTOCOLS[p].iters, SEEDS[0], label(p, s))) for s in settings]
    return plan


def curve_table(results: dict[str, dict]) -> list[str]:
    """Val and test PSNR along each curve run's training, next to the 800-iteration run of the same sizes and setting,
    or the budget rule's setting at 800 where the rule names them apart (does quality hold as the budget grows?)."""
    lines = []
    for r in sorted(results.values(), key=lambda r: r["key"]):
        if "curve" not in r:
            continue
        groups = rows_by(results, r["scene"], CURVE_BASE[r["protocol"]], r["method"])
        setting = r["setting"] if r["setting"] in groups else RULE_AT_800.get((r["method"], r["setting"]), "")
        short = [x for x in groups.get(setting, []) if x["seed"] == r["seed"]]
        steps = " · ".join(f"{int(step)}: {val:.2f} / {test:.2f}" for step, val, test in r["curve"])
        against = f"{short[0]['val_psnr']:.2f} / {short[0]['psnr']:.2f}" if short else "—"
        if short and setting != r["setting"]:
            against += f" (`{setting}`)"
        lines.append(f"| {r['scene']} | {r['method']} | `{r['setting']}` | {against} | {steps} |")
    if not lines:
        return []
    return [
        "Along the budget (the `curve` stage): one run of 3000 iterations, its checkpoints every "
        f"{CURVE_EVERY} iterations evaluated on val and test, against a run of 800 iterations with the same sizes and "
        "setting (its schedules are fractions of its own length, so step 800 of the long run is not the short run). "
        "Val / test PSNR:",
        "",
        "| scene | method | setting | 800-iteration run | 3000-iteration run, step: val / test |",
        "|---|---|---|---|---|",
        *lines,
        "",
    ]


def equal_time_lines(results: dict[str, dict]) -> list[str]:
    """A final cutoff 0.7 costs 1.3 × the wall time at P-CPU: is it better than 1.3 × the iterations without it?"""
    lines = []
    for scene, setting in (("lego", "wd0-nodecay"),):
        longer = rows_by(results, scene, "pcpu1040", "fourierf-vm").get(setting, [])
        capped = rows_by(results, scene, "pcpu", "fourierf-vm").get(f"{setting}-ffinal0.7", [])
        if longer and capped:
            val, test = ([fmt([r[k] for r in rows], 2) for rows in (longer, capped)] for k in ("val_psnr", "psnr"))
            lines.append(
                f"- {scene}, fourierf-vm, equal wall time: `{setting}` at 1040 iterations val {val[0]}, test {test[0]} "
                f"({len(longer)} seeds) against `{setting}-ffinal0.7` at 800 val {val[1]}, test {test[1]} "
                f"({len(capped)} seeds)"
            )
    return lines


def p_mid_along_the_budget(results: dict[str, dict]) -> list[str]:
    """Does quality hold as the budget grows? Fern at P-MID's sizes and `lr0.08`, 800 against 3000 iterations, for
    each method: the first seed's runs, the only seed the 800-iteration protocol ran, in whatever order recorded."""
    lines = []
    for m in METHODS:
        short, long = (
            [r for r in rows_by(results, "fern", p, m).get("lr0.08", []) if r["seed"] == SEEDS[0]]
            for p in ("pmid800", "pmid")
        )
        if short and long:
            lines.append(
                f"- fern, {m}, P-MID sizes, `lr0.08`, 800 → 3000 iterations: val {short[0]['val_psnr']:.2f} → "
                f"{long[0]['val_psnr']:.2f}, test {short[0]['psnr']:.2f} → {long[0]['psnr']:.2f}"
            )
    return lines


RULE_ALONG_THE_BUDGET = {
    "fourierf-vm": (
        ("pcpu", "lr0.08-tvconst-tv6-alphamask0.25-zfree"),
        ("pcpu3000", "lr0.08-tvconst-ramp0.2667-tv4-revive1"),
    ),
    "tensorf-vm": (("pcpu", "lr0.08-tvconst-tv6-alphamask0.25"), ("pcpu3000", "lr0.08-tvconst-tv4-revive1")),
}
"""fern, each method: the budget rule's settings at 800 and at 3000 iterations of P-CPU's sizes (grid lr 0.08; at 800
constant TV 6 and the occupancy update at step 200, fourierf-vm's band opening over the whole run with the density
filtered on the image plane; at 3000 constant TV 4, fourierf-vm's band open over the first 800 on every axis, and for
both a dark density field revived at its first dark batch), seed 20211202."""


RULE_AT_800 = {
    **{(method, long): short for method, ((_, short), (_, long)) in RULE_ALONG_THE_BUDGET.items()},
    ("fourierf-vm", "lr0.08-tvconst-ramp0.2667-tv4"): "lr0.08-tvconst-tv4",  # session 19's rule, its curve run
}
"""(method, the rule's 3000-iteration setting) -> the rule's 800-iteration setting, where the two are named apart."""


def rule_along_the_budget(results: dict[str, dict]) -> list[str]:
    """Does a user's run under the budget rule get better as the budget grows from 800 to 3000 iterations?"""
    lines = []
    for method, ((p_short, short), (p_long, long)) in RULE_ALONG_THE_BUDGET.items():
        short_rows = [r for r in rows_by(results, "fern", p_short, method).get(short, []) if r["seed"] == SEEDS[0]]
        long_rows = [r for r in rows_by(results, "fern", p_long, method).get(long, []) if r["seed"] == SEEDS[0]]
        if short_rows and long_rows:
            a, b = short_rows[0], long_rows[0]
            lines.append(
                f"- fern, {method}, the budget rule's settings at P-CPU sizes: `{short}` at 800 iterations val "
                f"{a['val_psnr']:.2f}, test {a['psnr']:.2f} → `{long}` at 3000 val {b['val_psnr']:.2f}, test "
                f"{b['psnr']:.2f}"
            )
    return lines


@dataclass(frozen=True)
class Target:
    """A quality target: fourierf-vm's val choice at a protocol leads tensorf-vm's by ``lead`` dB of test PSNR (and
    reads at least ``floor``). Each method chooses on val among ``fourierf`` / ``tensorf`` (every setting it ran where
    empty), so a target can name the baseline it is read against: TensoRF searched as hard as FourieRF, or TensoRF at
    its published settings with only its learning rate chosen."""

    scene: str
    protocol: str
    lead: float
    floor: float | None = None
    fourierf: tuple[str, ...] = ()
    tensorf: tuple[str, ...] = ()
    against: str = "each method at its val choice"


TARGETS = (
    Target("lego", "pcpu", 0.5, 22.0, fourierf=("wd0-nodecay-lr0.04-tv4-comp8-f0.05-bgwarm-ent0.00003",),
           against="fourierf-vm's default (the budget rule's own setting), tensorf-vm at its val choice"),
    Target("lego", "pcpu", 0.5, 22.0),
    Target("lego", "pmid", 1.0),
    Target("fern", "pmid", 2.0, 20.0, tensorf=("preset", "lr0.08"),
           against="tensorf-vm at its val-chosen learning rate, TensoRF's own decaying TV 1 and nothing else tuned"),
    Target("fern", "pmid", 2.0, 20.0, against="each method at its val choice (tensorf-vm's TV and Floaters-No-More "
           "chosen on val too)"),
)  # fmt: skip
"""The few-shot quality issue's targets, each against the baseline it names (fern: a learning rate; lego: every
setting) and, where that baseline is weaker than TensoRF searched as hard as FourieRF, against that one too."""


def targets_table(results: dict[str, dict], targets: Sequence[Target] = TARGETS) -> list[str]:
    """Each target as measured: both methods' choices, the lead in test PSNR (per seed where both ran the same
    seeds) and by how much it is met or missed."""
    lines = []
    for t in targets:
        picked, rows = {}, {}
        for method, allowed in (("fourierf-vm", t.fourierf), ("tensorf-vm", t.tensorf)):
            groups = rows_by(results, t.scene, t.protocol, method)
            groups = {s: r for s, r in groups.items() if not allowed or s in allowed}
            picked[method] = chosen_setting(groups)
            rows[method] = groups.get(picked[method], [])
        if not all(rows.values()):
            continue
        test = {m: {r["seed"]: r["psnr"] for r in rows[m]} for m in METHODS}
        own, baseline = (float(np.mean(list(test[m].values()))) for m in METHODS)
        lead = own - baseline
        shared = [seed for seed in SEEDS if seed in test["fourierf-vm"] and seed in test["tensorf-vm"]]
        per_seed = ", ".join(f"{test['fourierf-vm'][s] - test['tensorf-vm'][s]:+.2f}" for s in shared)
        short = [f"lead by {t.lead - lead:.2f}"] if lead < t.lead else []
        if t.floor is not None and own < t.floor:
            short.append(f"PSNR by {t.floor - own:.2f}")
        floor = f"≥ {t.floor:.1f} dB and " if t.floor is not None else ""
        cells = [f"`{picked[m]}`, {fmt(list(test[m].values()), 2)} ({len(test[m])})" for m in METHODS]
        status = "missed: " + ", ".join(short) if short else "met"
        lines.append(
            f"| {t.scene}, {PROTOCOLS[t.protocol].name}: fourierf-vm {floor}≥ +{t.lead:.1f} dB; {t.against} | "
            f"{cells[0]} | {cells[1]} | **{lead:+.2f}** ({per_seed}) | {status} |"
        )
    if not lines:
        return []
    return [
        "The quality targets, measured (test PSNR, mean ± std over the seeds; the lead per seed in brackets, seeds "
        f"{', '.join(map(str, SEEDS))}; each choice made on val among the settings the baseline allows):",
        "",
        "| target | fourierf-vm: setting, test PSNR (seeds) | tensorf-vm: setting, test PSNR (seeds) | lead | status |",
        "|---|---|---|---|---|",
        *lines,
        "",
    ]


REPEATS = "repeats.jsonl"
"""Beside the results: other runs of a key that was run again (the results keep one row a key), each with a
``repeat`` note that says what that run was: the spread between two runs of one setting and seed, on a GPU or on a
CPU on more than one thread (or with an earlier tree's code)."""


def read_repeats(path: Path) -> list[dict]:
    """Every row of ``repeats.jsonl``: unlike the results, a key may hold several (one a rerun)."""
    if not path.exists():
        return []
    return [json.loads(line) for line in path.read_text().splitlines() if line.strip()]


def later_seeds_table(results: dict[str, dict], repeats: Sequence[dict]) -> list[str]:
    """Every setting run on each later seed on a GPU, with its earlier repeats: the ReLU rules and the neighbours of a
    choice compared where they ran side by side, read against the spread between repeats (GPU training is not
    bit-reproducible: grid_sample's CUDA backward accumulates with atomics)."""
    later = SEEDS[1:]
    groups: dict[tuple[str, str, str, str, str], dict[int, dict]] = {}
    for r in [*results.values(), *repeats]:
        if r.get("device") == "cuda" and r["seed"] in later:
            group = (r["scene"], r["protocol"], r["method"], r["setting"], r.get("repeat", ""))
            groups.setdefault(group, {})[r["seed"]] = r
    lines = []
    for (scene, protocol, method, setting, note), by_seed in sorted(groups.items()):
        if set(by_seed) != set(later):
            continue
        rows = [by_seed[seed] for seed in later]
        cells = " | ".join(f"{r['val_psnr']:.2f} / {r['psnr']:.2f}" for r in rows)
        val, test = (np.mean([r[k] for r in rows]) for k in ("val_psnr", "psnr"))
        lines.append(
            f"| {scene} | {PROTOCOLS[protocol].name} | {method} | `{setting}`{f' ({note})' if note else ''} | {cells} "
            f"| {val:.2f} / {test:.2f} |"
        )
    if not lines:
        return []
    seeds = " | ".join(f"seed {seed}: val / test" for seed in later)
    return [
        f"Settings run on seeds {', '.join(map(str, later))} on a GPU (an H100; runs of one session at once), beside "
        "their earlier repeats: `-plain` is TensoRF's ReLU for the density, `-revive1` revives every dark batch (the "
        "budget rule's for a forward-facing run over 800 iterations), no suffix the field's default, which revives "
        "a field only when it is dead (`dead_start.py`). GPU training is not bit-reproducible "
        "(grid_sample's CUDA backward accumulates with atomics), so a repeat of one setting and seed is the spread "
        "a difference must clear.",
        "",
        f"| scene | protocol | method | setting | {seeds} | mean val / test |",
        "|---|---|---|---|" + "---|" * len(later) + "---|",
        *lines,
        "",
    ]


def threads_cell(rows: Iterable[dict]) -> str:
    """The CPU threads the rows trained on, as one cell: ``1`` where every CPU row says one (bit-reproducible), ``?``
    for rows from before rows recorded it (session 48), ``—`` where none ran on a CPU."""
    cpu = [r for r in rows if r.get("device") == "cpu"]
    if not cpu:
        return "—"
    return " / ".join(sorted({str(r.get("train_threads") or "?") for r in cpu}))


def cpu_reruns_table(results: dict[str, dict], repeats: Sequence[dict]) -> list[str]:
    """Every CPU run of a key that ran twice, beside the row the report reads: how far one setting and seed moved
    between two CPU runs (on more than one thread, or across a change of code) is the spread a difference must clear."""
    lines = []
    for other in sorted((r for r in repeats if r.get("device") == "cpu" and r["key"] in results),
                        key=lambda r: r["key"]):  # fmt: skip
        kept = results[other["key"]]
        cells = [f"{r['val_psnr']:.2f} / {r['psnr']:.2f} ({threads_cell([r])})" for r in (kept, other)]
        lines.append(
            f"| {kept['scene']} | {PROTOCOLS[kept['protocol']].name} | {kept['method']} | `{kept['setting']}` | "
            f"{kept['seed']} | {cells[0]} | {cells[1]} | {other['repeat']} |"
        )
    if not lines:
        return []
    return [
        "CPU runs of one setting and seed run twice: the row the tables above read and the other run (`repeats.jsonl`"
        "), val / test PSNR (CPU threads; ? = not recorded). Only a one-thread CPU run is bit-reproducible.",
        "",
        "| scene | protocol | method | setting | seed | read above | other run | what the other run was |",
        "|---|---|---|---|---|---|---|---|",
        *lines,
        "",
    ]


def comparable_seconds(rows: dict[str, list[dict]]) -> str:
    """Each method's mean training seconds over its runs on one device both methods ran on (the one holding most of
    their runs), as the summary's cell: a mean over a CPU run and two GPU runs set beside three CPU runs would read as
    a speed gap."""
    shared = sorted(set.intersection(*({r["device"] for r in rows[m]} for m in METHODS)))
    if not shared:
        return "— (no shared device)"
    device = max(shared, key=lambda d: sum(r["device"] == d for m in METHODS for r in rows[m]))
    secs = [np.mean([r["train_seconds"] for r in rows[m] if r["device"] == device]) for m in METHODS]
    return " / ".join(f"{t:.0f}" for t in secs) + f" ({device})"


def recording_machines(rows: Iterable[dict]) -> str:
    """Where the rows ran: they span many sessions' machines, so the machine that writes the report says nothing of
    them. Rows record their CPU since session 41; older ones do not."""
    named = sorted({r["machine"] for r in rows if "machine" in r})
    since = f"; rows that record theirs: {'; '.join(named)}" if named else ""
    return f"each session's own (2-core CPUs, torch 2.13.0+cpu; an H100 where the device is cuda){since}"


def report(args: argparse.Namespace) -> list[str]:
    results = load_results(args.results)
    body = section_head(
        "Few-shot quality at two budgets: P-CPU and P-MID, settings chosen on val",
        "python benchmarks/pmid.py sweep|seeds|report",
        "Protocols and settings: the script's docstring. Each method at its own val-chosen setting (best mean val PSNR "
        f"over seeds {', '.join(map(str, SEEDS))} among the settings run on all of them, else best val PSNR of seed "
        f"{SEEDS[0]}); test PSNR of that setting only, mean ± std over the seeds run. PSNRs agree across "
        "devices up to float rounding and random streams. Training seconds are the device's and were taken while other "
        "work shared the machine: they are no speed measurement (the speed benchmarks are the interleaved ones).",
        machine=recording_machines(results.values()),
    )
    summary = [
        "| scene | protocol | device | fourierf-vm: setting, test PSNR (seeds) | tensorf-vm: setting, test PSNR (seeds)"
        " | gap | CPU threads | train s (f / t) |",
        "|---|---|---|---|---|---|---|---|",
    ]
    sweeps: list[str] = []
    for scene in ("lego", "fern"):
        for p in PROTOCOLS:
            tables = {m: rows_by(results, scene, p, m) for m in METHODS}
            if not all(tables.values()):
                continue
            name = PROTOCOLS[p].name
            picked = {m: chosen_setting(tables[m]) for m in METHODS}
            rows = {m: tables[m][picked[m]] for m in METHODS}
            test = {m: [r["psnr"] for r in rows[m]] for m in METHODS}
            device = "/".join(sorted({r["device"] for m in METHODS for r in rows[m]}))
            cells = [f"`{picked[m]}`, {fmt(test[m], 2)} ({len(test[m])})" for m in METHODS]
            gap = np.mean(test["fourierf-vm"]) - np.mean(test["tensorf-vm"])
            summary.append(
                f"| {scene} | {name} | {device} | {cells[0]} | {cells[1]} | **{gap:+.2f}** | "
                f"{threads_cell(r for m in METHODS for r in rows[m])} | {comparable_seconds(rows)} |"
            )
            for s in SETTINGS[scene]:
                vals = [val_cell(tables[m][s]) if s in tables[m] else "—" for m in METHODS]
                if vals != ["—", "—"]:
                    sweeps.append(f"| {scene} | {name} | {s} | " + " | ".join(vals) + " |")
    body += [*summary, ""]
    body += targets_table(results)
    body += p_mid_along_the_budget(results)
    body += equal_time_lines(results)
    body += rule_along_the_budget(results)
    body += ["", *curve_table(results)]
    repeats = read_repeats(args.results.with_name(REPEATS))
    body += later_seeds_table(results, repeats)
    body += cpu_reruns_table(results, repeats)
    body += [
        f"Validation PSNR of every setting tried, seed {SEEDS[0]}, and the mean over all {len(SEEDS)} seeds where "
        "they were run, or over the seeds named where only some were (the choice above is the best all-seed mean of "
        "each column, else its best first seed):",
        "",
    ]
    body += ["| scene | protocol | setting | fourierf-vm val | tensorf-vm val |", "|---|---|---|---|---|", *sweeps, ""]
    for grid in GRIDS:
        if (REPO / grid.path).is_file():
            heads = " | ".join(("ground truth", *grid.columns))
            body += [
                f"{grid.heading}: `{grid.path}` (`python benchmarks/picture_grid.py`, {grid.runs}; {grid.views}). "
                f"Columns: {heads}; rows: RGB, depth (turbo, dark = near, one range per view), accumulation.",
                "",
                f"![{grid.scene}: {', '.join(('ground truth', *grid.columns))}; rgb, depth, accumulation]({grid.path})",
                "",
                f"What the grid shows (read by eye, not measured): {grid.reading}",
                "",
            ]
    return body


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("stage", choices=("sweep", "seeds", "curve", "merge", "report"))
    ap.add_argument("--protocol", nargs="+", choices=tuple(PROTOCOLS), default=None,
                    help="default: pcpu pmid pmid800 (the curve stage: pcpu3000)")  # fmt: skip
    ap.add_argument("--scene", nargs="+", choices=tuple(SETTINGS), default=list(SETTINGS))
    ap.add_argument("--data", type=Path, default=REPO.parent / "shared" / "data",
                    help="folder holding blender/lego and llff/fern")  # fmt: skip
    ap.add_argument("--lpips", type=Path, default=REPO.parent / "shared" / "lpips" / "lpips_alex_v0.1.pth")
    ap.add_argument("--work", type=Path, default=REPO / "outputs" / "bench_pmid", help="run folders and logs")
    ap.add_argument("--results", type=Path, default=REPO / "benchmarks" / "results" / "pmid" / "results.jsonl",
                    help="one row per finished run (the report reads it; finished runs are skipped)")  # fmt: skip
    ap.add_argument("--device", default="cpu", choices=("cpu", "cuda"))
    ap.add_argument("--only", nargs="+", default=None, help="sweep only these settings (names from SETTINGS)")
    ap.add_argument("--methods", nargs="+", choices=METHODS, default=None, help="run only these methods")
    ap.add_argument("--seeds", nargs="+", type=int, choices=SEEDS[1:], default=None,
                    help="the seeds stage runs only these of the later seeds (default: all)")  # fmt: skip
    ap.add_argument("--jobs", type=int, default=1, help="trainings at once")
    ap.add_argument("--threads", type=int, default=1,
                    help="CPU threads per training and its evaluations (1: a CPU run is bit-reproducible; more are "
                         "faster alone, but sum floats in a varying order)")  # fmt: skip
    ap.add_argument("--again", metavar="NOTE", default=None,
                    help="run the plan's recorded runs again too; each earlier row moves to repeats.jsonl with NOTE "
                         "(what differed then, e.g. 'threads not recorded')")  # fmt: skip
    ap.add_argument("--rows", nargs="+", type=Path, default=None, metavar="FILE",
                    help="merge: results files written elsewhere (another --results, the device)")  # fmt: skip
    ap.add_argument("--markdown", type=Path, default=REPO / "BENCHMARKS.md")
    args = ap.parse_args()
    if args.protocol is None:
        args.protocol = ["pcpu3000"] if args.stage == "curve" else ["pcpu", "pmid", "pmid800"]
    if args.threads < 1:
        sys.exit(f"error: --threads {args.threads} must be at least 1; pass e.g. --threads 2, or omit it for 1")
    if args.again is not None and (args.stage == "report" or not args.again.strip()):
        sys.exit("error: --again NOTE reruns the runs of a sweep, seeds or curve stage (or merges runs of recorded "
                 "keys) and needs a note saying what differed then, e.g. --again 'threads not recorded'")  # fmt: skip
    if (args.rows is None) != (args.stage != "merge"):
        sys.exit("error: --rows FILE ... goes with the merge stage, and the merge stage needs it: "
                 "pmid.py merge --rows other/results.jsonl")  # fmt: skip
    if args.seeds and args.stage != "seeds":
        sys.exit(f"error: --seeds picks the later seeds of the seeds stage; drop it for the {args.stage} stage")
    known = {name for scene in args.scene for name in SETTINGS[scene]}
    unknown = sorted(set(args.only or ()) - known)
    if unknown:
        scenes = " ".join(args.scene)
        sys.exit(f"error: --only {' '.join(unknown)}: no such setting for {scenes}; known: {sorted(known)}")
    args.work.mkdir(parents=True, exist_ok=True)
    args.results.parent.mkdir(parents=True, exist_ok=True)
    if args.stage == "report":
        print(update_benchmarks_md(args.markdown, BEGIN, END, report(args)))
        return
    if args.stage == "merge":
        try:
            print("\n".join(merge(args.results, args.rows, args.again)))
        except ValueError as err:
            sys.exit(f"error: {err}")
        return
    for scene in args.scene:
        if not (args.data / ("blender/lego/transforms_train.json" if scene == "lego" else "llff/fern")).exists():
            sys.exit(f"error: {scene} not found under {args.data}; pass --data FOLDER")
    plans = {"sweep": sweep_plan, "seeds": seeds_plan, "curve": curve_plan}
    run_all(plans[args.stage](args), args)


if __name__ == "__main__":
    main()
