"""The equal-iterations section of BENCHMARKS.md, a pure function of the stage's rows (``run.py equal-iterations``).

Per scene: test PSNR / SSIM / LPIPS, iterations and training time of each method at the suite's iteration budget;
then the two comparisons the paper's systems call for: TensoRF as published against FourieRF as in the paper (beside
the paper's gap at full scale), and ZeroRF with its alpha term against without it.
"""

from __future__ import annotations

from collections.abc import Sequence

from harness import Suite, markers, section_head

BEGIN, END = markers("equal-iterations", "report.py")
COMMAND = "python benchmarks/run.py equal-iterations --scene lego fern --jobs 2, then python benchmarks/report.py"
TITLE = "Equal iterations: the paper's systems at the default CPU run"
PAPER, BASELINE = "fourierf-vm-paper", "tensorf-vm-published"
ALPHA, NO_ALPHA = "zerorf-vm", "zerorf-vm-no-alpha"


def find(rows: Sequence[dict], scene: str, method: str) -> dict | None:
    """The trained row of a method (or variant) on a scene, or None."""
    return next((r for r in rows if (r["scene"], r["method"]) == (scene, method) and "psnr" in r), None)


def gap(rows: Sequence[dict], scene: str, ahead: str, behind: str) -> float | None:
    """Test PSNR of ``ahead`` minus ``behind`` on a scene in dB, or None where either has no row."""
    first, second = find(rows, scene, ahead), find(rows, scene, behind)
    return None if first is None or second is None else first["psnr"] - second["psnr"]


def db(value: float | None) -> str:
    return "not run" if value is None else f"{value:+.2f} dB"


def scene_table(rows: Sequence[dict], scene: str, methods: Sequence[str]) -> list[str]:
    lines = [
        f"### {scene}",
        "",
        "| method | test PSNR | SSIM | LPIPS | iterations | training s | s/iteration |",
        "|---|---|---|---|---|---|---|",
    ]
    for method in methods:
        row = find(rows, scene, method)
        if row is None:
            lines.append(f"| {method} | not run | | | | | |")
            continue
        lines.append(
            f"| {method} | {row['psnr']:.2f} | {row['ssim']:.3f} | {row['lpips']:.3f} | {row['iterations']} | "
            f"{row['trained_seconds']:.0f} | {row['seconds_per_iteration']:.2f} |"
        )
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
        "covers it. Training seconds come from a shared, loaded machine (other work ran beside these points); the "
        "equal-time section has the quiet-machine speeds.",
        machine=f"{machines}, one thread a run",
    )
    if not rows:
        return [*body, "No points are recorded yet.", ""]
    for scene in suite.equal_time["scenes"]:
        variants = stage.get("variants", {})
        methods = [m for m in stage["methods"] if scene in variants.get(m, {}).get("scenes", [scene])]
        body += scene_table(rows, scene, methods)
    return [*body, *derived_lines(rows, suite)]
