"""Where a run computes and how its random draws are seeded (shared by training and by loading a run)."""

from __future__ import annotations

import random

import numpy as np
import torch

from fourierf_plugin.utils.errors import fail


def pick_device(choice: str) -> torch.device:
    """CUDA when available (or asked for), else CPU."""
    if choice == "auto":
        return torch.device("cuda" if torch.cuda.is_available() else "cpu")
    if choice == "cuda" and not torch.cuda.is_available():
        fail("--device cuda was asked for but no CUDA device is available", "use --device auto or --device cpu")
    return torch.device(choice)


def seed_everything(seed: int) -> torch.Generator:
    """Seed python, numpy and torch; return the generator that drives every random draw of a run."""
    random.seed(seed)
    np.random.seed(seed % 2**32)
    torch.manual_seed(seed)
    return torch.Generator().manual_seed(seed)
