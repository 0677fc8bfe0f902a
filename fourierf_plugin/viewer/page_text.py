"""The page's words: the status beside the picture, the hint at a zero cutoff, the depth legend, and errors said in
the page's terms (its controls, not the command line's flags). Pure functions of numbers, so they are tested alone.
"""

from __future__ import annotations

import re

from fourierf_plugin.viewer.viewed_run import TrainingProgress

ZERO_CUTOFF_HINT = (
    "A density cutoff of 0 keeps only the field's mean, so the picture is nearly blank: raise the density slider "
    "to see the coarse scene the curriculum starts from."
)

_PAGE_WORDS = {
    "--frequency-cap": "the density cutoff",
    "--level": "the surface level",
    "--resolution": "the mesh resolution",
    "--output-path": "the mesh file",
    "--bbox-min": "the mesh box",
    "--bbox-max": "the mesh box",
    "--min-component-faces": "the smallest piece kept",
}


def for_the_page(message: str) -> str:
    """``message`` with each command-line flag it names replaced by what the page calls it."""
    return re.sub(r"--[a-z][a-z0-9-]*", lambda m: _PAGE_WORDS.get(m.group(0), "a setting"), message)


def progress_lines(progress: TrainingProgress, shown_step: int) -> list[str]:
    """The run's state: training (step, cutoffs, loss and PSNR) or finished / stopped at its last step."""
    if progress.finished:
        how = "stopped (interrupted)" if progress.interrupted else "finished"
        first = f"**{how} at step {progress.step}** of {progress.max_steps}: the page shows the final weights"
    else:
        first = f"**training** step {progress.step} / {progress.max_steps} (picture from step {shown_step})"
    lines = [first, f"run cutoffs density {progress.f_density:.2f}, colour {progress.f_color:.2f}"]
    numbers = [f"{k} {progress.metrics[k]:.4g}" for k in ("loss", "psnr") if k in progress.metrics]
    if numbers:
        lines.append(" · ".join(numbers))
    return lines


def status_text(
    step: int,
    run_cutoffs: tuple[float, float],
    progress: TrainingProgress | None,
    shown_cutoffs: tuple[float, float] | None,
    last_render_seconds: float | None,
) -> str:
    """The status markdown: the run (saved or live), the cutoffs shown, the last picture's time, a hint at 0."""
    if progress is None:
        lines = [f"**step** {step} · run cutoffs density {run_cutoffs[0]:.2f}, colour {run_cutoffs[1]:.2f}"]
    else:
        lines = progress_lines(progress, step)
    if shown_cutoffs is not None:
        lines.append(f"shown at density {shown_cutoffs[0]:.2f}, colour {shown_cutoffs[1]:.2f}")
        if shown_cutoffs[0] <= 0.0:
            lines.append(f"*{ZERO_CUTOFF_HINT}*")
    if last_render_seconds is not None:
        lines.append(f"last picture {last_render_seconds:.2f} s")
    return "  \n".join(lines)


def depth_legend(near: float, far: float, colormap: str = "turbo") -> str:
    """What a depth picture's colours mean: the colormap's low end is ``near``, its high end ``far``."""
    return (
        f"**depth** ({colormap}): dark blue {near:.3g} → dark red {far:.3g} scene units from the camera; "
        "empty space white"
    )


def final_progress(stage: int, stages: int, side: int, fraction: float) -> str:
    """The final picture's progress: which coarse-to-full stage and how far through it."""
    return f"final picture: stage {stage} / {stages} ({side} px), {100 * fraction:.0f} %"
