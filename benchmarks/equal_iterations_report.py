"""The equal-iterations section of BENCHMARKS.md, a pure function of the stage's rows (``run.py equal-iterations``).

Per scene: test PSNR / SSIM / LPIPS, iterations and training time of each method at each iteration budget it ran
(the suite's, or a shorter one where a method is too slow for it); then the two comparisons the paper's systems call
for, each between rows of the same iterations: TensoRF as published against FourieRF as in the paper (beside the
paper's gap at full scale), and ZeroRF with its alpha term against without it.
"""

from __future__ import annotations

from collections.abc import Sequence

from harness import Suite, markers, section_head

BEGIN, END = markers("equal-iterations", "report.py")
COMMAND = "python benchmarks/run.py equal-iterations --scene lego fern --jobs 2, then python benchmarks/report.py"
TITLE = "Equal iterations: the paper's systems at the default CPU run"
PAPER, BASELINE = "fourierf-vm-paper", "tensorf-vm-published"
ALPHA, NO_ALPHA = "zerorf-vm", "zerorf-vm-no-alpha"


def trained(rows: Sequence[dict], scene: str, method: str) -> list[dict]:
    """The trained rows of a method (or variant) on a scene, most iterations first."""
    found = [r for r in rows if (r["scene"], r["method"]) == (scene, method) and "psnr" in r]
    return sorted(found, key=lambda r: -r["iterations"])


def gap(rows: Sequence[dict], scene: str, ahead: str, behind: str) -> tuple[float, int] | None:
    """Test PSNR of ``ahead`` minus ``behind`` on a scene in dB at the most iterations both ran (and those
    iterations), or None where they share no budget."""
    for first in trained(rows, scene, ahead):
        second = next((r for r in trained(rows, scene, behind) if r["budget"] == first["budget"]), None)
        if second is not None:
            return first["psnr"] - second["psnr"], first["iterations"]
    return None


def db(found: tuple[float, int] | None) -> str:
    return "not run at equal iterations" if found is None else f"{found[0]:+.2f} dB at {found[1]} iterations"


def scene_table(rows: Sequence[dict], scene: str, methods: Sequence[str]) -> list[str]:
    lines = [
        f"### {scene}",
        "",
        "| method | test PSNR | SSIM | LPIPS | iterations | training s | s/iteration |",
        "|---|---|---|---|---|---|---|",
    ]
    for method in methods:
        found = trained(rows, scene, method)
        lines += [
            f"| {method} | {row['psnr']:.2f} | {row['ssim']:.3f} | {row['lpips']:.3f} | {row['iterations']} | "
            f"{row['trained_seconds']:.0f} | {row['seconds_per_iteration']:.2f} |"
            for row in found
        ] or [f"| {method} | not run | | | | | |"]
    return [*lines, ""]


def derived_lines(rows: Sequence[dict], suite: Suite) -> list[str]:
    """FourieRF (paper) over TensoRF (published) on each scene beside the paper's gap; ZeroRF's alpha term on lego."""
    paper_gap = suite.equal_time["iterations"]["paper_gap"]
    gaps = [
        f"{scene} {db(gap(rows, scene, PAPER, BASELINE))} (paper at full scale: {paper_gap[scene]:+.1f} dB)"
        for scene in suite.equal_time["scenes"]
    ]
    return [
        f"- {PAPER} minus {BASELINE}, test PSNR: " + "; ".join(gaps) + ".",
        f"- {ALPHA} with minus without its alpha term ({NO_ALPHA}) on lego: {db(gap(rows, 'lego', ALPHA, NO_ALPHA))}.",
        "",
    ]


def section(rows: Sequence[dict], suite: Suite) -> list[str]:
    stage = suite.equal_time["iterations"]
    machines = "; ".join(sorted({r["machine"] for r in rows})) or "none yet"
    side = 400 // suite.protocols[suite.equal_time["protocol"]].lego_downscale  # Blender's images are 400×400
    body = section_head(
        TITLE,
        COMMAND,
        f"Each point is a user's run at {stage['budget'].removesuffix('it')} iterations: `fourierf-train METHOD "
        "--max-num-iterations N --threads 1` with no size flag (sized as the default CPU run, the short-run rules "
        f"applying as they would), then `fourierf-eval` on the test views; lego at {side}×{side}. {NO_ALPHA} is "
        "zerorf-vm with `--pipeline.model.alpha-weight 0`, on lego only (fern's images carry no alpha). freenerf is "
        "left out: at over ten seconds an iteration on this CPU, the budget takes hours; the equal-time section "
        "covers it. A method too slow for that budget here runs a shorter one (`--budget Nit`), the iterations "
        "column saying which; each derived line compares rows of equal iterations only. Training seconds come from "
        "a shared, loaded machine (other work ran beside these points); the equal-time section has the "
        "quiet-machine speeds.",
        machine=f"{machines}, one thread a run",
    )
    if not rows:
        return [*body, "No points are recorded yet.", ""]
    for scene in suite.equal_time["scenes"]:
        variants = stage.get("variants", {})
        methods = [m for m in stage["methods"] if scene in variants.get(m, {}).get("scenes", [scene])]
        body += scene_table(rows, scene, methods)
    return [*body, *derived_lines(rows, suite)]
