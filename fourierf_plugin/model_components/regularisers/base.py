"""What every few-shot regulariser is: a term on the training rays, on rays from unseen poses, or a gradient scale.

The model builds the regularisers its config asks for (``FourieRFModelConfig.regularisers``) and runs each through the
same three hooks: ``ray_term`` on every training render, ``unseen_loss`` on the renders of its unseen-view rays, and
``gradient_scale`` on the samples' gradients. A regulariser that needs none of them leaves its hook at the default.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar

from torch import Tensor


@dataclass(frozen=True)
class TrainingRays:
    """What one training render hands the regularisers: its rays' densities, samples and compositing weights."""

    sigma: Tensor
    """[R, N] densities at the samples (0 outside occupied cells)."""
    t: Tensor
    """[R, N] ray parameters of the samples."""
    deltas: Tensor
    """[R, N] interval lengths (the last 0)."""
    weights: Tensor
    """[R, N] compositing weights."""
    accumulation: Tensor
    """[R] opacity of each ray."""
    near: float
    far: float
    distance_scale: float
    """Multiplies σδ in compositing."""


@dataclass(frozen=True)
class UnseenViews:
    """Rays a regulariser renders from poses between the training cameras: ``patches`` square patches of ``size``²."""

    patches: int
    size: int

    @property
    def rays(self) -> int:
        return self.patches * self.size**2


class Regulariser:
    """One few-shot regulariser; subclasses override the hooks they use."""

    name: ClassVar[str]
    """Its term's key among the loss terms and the render's outputs."""
    unseen_name: ClassVar[str] = ""
    """The key of its unseen-view term among the loss terms."""
    weight: float
    """What its term is multiplied by (a subclass field)."""
    unseen: UnseenViews | None = None
    """The unseen-view rays it renders each step; None: none."""

    def ray_term(self, rays: TrainingRays) -> Tensor | None:
        """Its term on a training render's rays, unweighted (the render returns it under ``name``); None: none."""
        return None

    def loss(self, outputs: dict) -> Tensor | None:
        """Its weighted term on a training batch's outputs, or None where the render holds none."""
        return self.weight * outputs[self.name] if self.name in outputs else None

    def unseen_loss(self, outputs: dict) -> Tensor:
        """Its weighted term on the geometry-only render of its unseen-view rays (``unseen``)."""
        raise NotImplementedError

    def scales_gradients_at(self, step: int) -> bool:
        """Whether ``gradient_scale`` acts at ``step``."""
        return False

    def gradient_scale(self, t: Tensor) -> Tensor:
        """The factor [R, N] the samples' density and colour gradients are multiplied by (identity forward)."""
        raise NotImplementedError
