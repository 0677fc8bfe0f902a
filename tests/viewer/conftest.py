"""One trained tiny run shared by the viewer tests (training it once keeps them within seconds)."""

from __future__ import annotations

from pathlib import Path

import pytest

from fourierf_plugin.engine.trainer import Trainer
from tests.helpers import train_tiny

TRAINED_ITERS = 150
"""Enough for the bundled scene to show an object (20 iterations still render blank), so cutoffs visibly matter."""


@pytest.fixture(scope="session")
def trained_run(tmp_path_factory: pytest.TempPathFactory) -> tuple[Trainer, Path]:
    """The trainer (its model is the final one) and the run folder of a 150-iteration tiny run."""
    return train_tiny(tmp_path_factory.mktemp("viewer-run"), iters=TRAINED_ITERS)
