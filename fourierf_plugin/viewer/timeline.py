"""A saved run's timeline on the page: a step slider over the run's checkpoints (with the curriculum's cutoffs at
each), so a user scrubs through how the scene formed, and the meshes ``--export-mesh-at`` wrote beside it."""

from __future__ import annotations

import re
from pathlib import Path
from typing import TYPE_CHECKING, Protocol

from fourierf_plugin.engine.checkpoint import list_checkpoints, load_checkpoint
from fourierf_plugin.utils.console import warn
from fourierf_plugin.utils.errors import UserError
from fourierf_plugin.viewer.page_text import for_the_page

if TYPE_CHECKING:
    import viser

    from fourierf_plugin.viewer.viewed_run import ViewedRun


class Page(Protocol):
    """What the timeline needs of the page (``viewer.server.ViewerServer``)."""

    server: viser.ViserServer
    viewed: ViewedRun

    def follow_run_cutoffs(self) -> None: ...

    def refresh_status(self) -> None: ...

    def changed(self, moving: bool = True) -> None: ...


_STEP = re.compile(r"step-(\d+)\.(ckpt|ply)$")


def step_of(path: Path) -> int:
    """The step in a ``step-N.ckpt`` / ``step-N.ply`` name."""
    match = _STEP.search(path.name)
    if match is None:
        raise ValueError(f"{path.name} is not named step-N")
    return int(match.group(1))


def training_meshes(run_dir: Path) -> list[Path]:
    """The meshes written during training (``RUN/meshes/step-N.ply``), by step."""
    meshes = Path(run_dir) / "meshes"
    found = [p for p in meshes.glob("step-*.ply") if _STEP.search(p.name)] if meshes.is_dir() else []
    return sorted(found, key=step_of)


def timeline_text(steps: list[int], cutoffs: list[tuple[float, float]], shown: int, meshes: list[Path]) -> str:
    """The timeline's markdown: each checkpoint's step and the curriculum's cutoffs there, the meshes beside."""
    marks = [
        f"{'**' if step == shown else ''}step {step}: density {fd:.2f}, colour {fc:.2f}{'**' if step == shown else ''}"
        for step, (fd, fc) in zip(steps, cutoffs, strict=True)
    ]
    lines = marks or ["no checkpoint in this run's checkpoints/ folder"]
    if meshes:
        lines.append("meshes from training: " + ", ".join(f"{p.name} (step {step_of(p)})" for p in meshes))
    return "  \n".join(lines)


class Timeline:
    """The slider, its text, and loading a checkpoint's weights into the page's model when it moves."""

    def __init__(self, page: Page) -> None:
        self.page = page
        run_dir = page.viewed.run_dir
        self.checkpoints = list_checkpoints(run_dir / "checkpoints")
        self.steps = [step_of(p) for p in self.checkpoints]
        self.meshes = training_meshes(run_dir)
        gui = page.server.gui
        with gui.add_folder("Timeline"):
            self.slider = None
            if len(self.steps) >= 2:
                shown = self.steps.index(page.viewed.step) if page.viewed.step in self.steps else len(self.steps) - 1
                self.slider = gui.add_slider(
                    "Checkpoint", 0, len(self.steps) - 1, 1, shown,
                    marks=tuple((i, str(step)) for i, step in enumerate(self.steps)),
                    hint="scrub through the run's saved steps: the scene as it formed",
                )  # fmt: skip
                self.slider.on_update(lambda event: self.load(self.slider.value, event.client))
            self.text = gui.add_markdown(self._text())

    def _text(self) -> str:
        model = self.page.viewed.model
        return timeline_text(self.steps, [model.cutoffs(s) for s in self.steps], self.page.viewed.step, self.meshes)

    def load(self, index: object, client: object = None) -> bool:
        """Show checkpoint ``index`` (a page may send any value: anything but a checkpoint's index is ignored)."""
        if isinstance(index, bool) or not isinstance(index, (int, float)) or not 0 <= index < len(self.steps):
            return False
        index = int(index)
        if self.steps[index] == self.page.viewed.step:
            return False
        try:
            state = load_checkpoint(self.checkpoints[index])
            self.page.viewed.load_snapshot(state["pipeline"]["model"], int(state["step"]))
        except (UserError, OSError, KeyError, RuntimeError) as err:
            message = for_the_page(f"cannot show step {self.steps[index]}: {getattr(err, 'problem', err)}")
            warn(message)
            if client is not None and hasattr(client, "add_notification"):
                client.add_notification("Timeline", message, auto_close_seconds=8.0)
            return False
        self.page.follow_run_cutoffs()
        self.text.content = self._text()
        self.page.refresh_status()
        self.page.changed(moving=False)
        return True
