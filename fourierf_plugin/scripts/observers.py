"""The observers a training run asks for (``--viewer``, ``--vis tensorboard``), made where every layer may be imported.

Built before the trainer makes its run folder, so a missing extra or an impossible port stops the run before anything
is written. Each observer's module is imported only when asked for (the extras stay optional).
"""

from __future__ import annotations

from fourierf_plugin.engine.observers import TrainingObserver
from fourierf_plugin.engine.trainer import TrainerConfig


def build_observers(config: TrainerConfig) -> list[TrainingObserver]:
    observers: list[TrainingObserver] = []
    if config.vis == "tensorboard":
        from fourierf_plugin.vis.tensorboard_writer import TensorBoardObserver

        observers.append(TensorBoardObserver(image_every=config.vis_image_every))
    if config.viewer:
        from fourierf_plugin.viewer.live import LiveViewer

        observers.append(LiveViewer(config.viewer_port, config.viewer_max_slowdown, config.viewer_host))
    return observers


def after_training(observers: list[TrainingObserver], exit_code: int | None) -> None:
    """Once training returned (``exit_code`` None) or stopped on a signal: a live viewer may keep showing the
    finished run (``viewer.live``)."""
    for observer in observers:
        end = getattr(observer, "after_training", None)
        if end is not None:
            end(exit_code)
