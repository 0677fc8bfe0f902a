"""What every radiance field of this package shares: factors prepared once per iteration, and the model's interface.

``prepare(f_density, f_color)`` computes the factors every lookup and regulariser reads until the next ``prepare``
(low-passed copies of free grids, or a generator's outputs), with autograd when training; any resize invalidates
them, so a grid of an old shape is never read. ``filtered_at`` evaluates the field at other cutoffs for a while (an
export, a viewer) and then restores what was prepared.

The model reads a field only through this interface: ``density``/``rgb`` at world points, ``resolution``, ``aabb``,
``crop``/``upsample`` (its structure changes) and ``param_groups`` (what the optimiser updates, by group name).
"""

from __future__ import annotations

from collections.abc import Iterator, Sequence
from contextlib import contextmanager
from dataclasses import dataclass

import torch
from torch import Tensor, nn

from fourierf_plugin.field_components import fourier
from fourierf_plugin.fields.grid_ops import FilteredFactors, GridOps


@dataclass
class FilteredGrids:
    """Both grids after the low-pass at one pair of cutoffs (one shared grid may stand for both)."""

    density: FilteredFactors
    appearance: FilteredFactors
    cutoffs: tuple[float, float]


class PreparedField(nn.Module):
    """The preparation and caching of a field's factors; subclasses say what ``filter`` makes and how it is read."""

    aabb: Tensor
    replaces_parameters: bool = True
    """Whether ``crop``/``upsample`` swap in new parameter tensors (the optimiser must then be rebuilt)."""

    def __init__(
        self, aabb: Tensor, ops: GridOps | None, plane_leakage: float = 0.0, mirror_boundary: bool = False
    ) -> None:
        super().__init__()
        self.ops = ops if ops is not None else GridOps()
        self.plane_leakage = float(plane_leakage)
        self.mirror_boundary = mirror_boundary
        self.register_buffer("aabb", aabb.detach().clone().float())
        self._filtered: FilteredGrids | None = None
        self._render_key: tuple | None = None

    # -- what a field defines ---------------------------------------------------------------------------------
    def filter(self, f_density: float, f_color: float) -> FilteredGrids:
        raise NotImplementedError

    @property
    def resolution(self) -> list[int]:
        raise NotImplementedError

    def density(self, xyz: Tensor) -> Tensor:
        raise NotImplementedError

    def rgb(self, xyz: Tensor, directions: Tensor | None) -> Tensor:
        raise NotImplementedError

    def crop(self, lo: Sequence[int], hi: Sequence[int], box: Tensor) -> None:
        """Keep vertices [lo, hi) per axis, which span ``box`` (the occupancy shrink)."""
        raise NotImplementedError

    def upsample(self, reso: Sequence[int]) -> None:
        """Continue at ``reso`` vertices per axis (call after ``prepare``: the free grids resize what it made)."""
        raise NotImplementedError

    def param_groups(self) -> dict[str, list[nn.Parameter]]:
        raise NotImplementedError

    @property
    def revived_batches(self) -> Tensor | None:
        """Training batches on which a dead density field was revived so far (None: its activation never revives)."""
        return None

    # -- the low-pass -----------------------------------------------------------------------------------------------
    def low_pass_planes(self, planes: Tensor, f: float) -> Tensor:
        """[..., H, W] planes at cutoff ``f``, with the field's plane leakage and boundary (periodic or mirror)."""
        if self.mirror_boundary:
            return fourier.mirrored(self.ops.filter_planes, planes, f, 2, self.plane_leakage)
        return self.ops.filter_planes(planes, f, self.plane_leakage)

    def low_pass_plane_along(self, plane: Tensor, f: float, spans: tuple[int, int], axes: Sequence[int]) -> Tensor:
        """A [..., H, W] plane spanning world axes ``spans = (m0, m1)`` (W along m0, H along m1), low-passed along
        those of them in ``axes``: the disc where both are, the line filter along the one where one is, unchanged
        where neither is (a curriculum on some axes only, e.g. a forward-facing scene's image plane)."""
        m0, m1 = spans
        if m0 in axes and m1 in axes:
            return self.low_pass_planes(plane, f)
        if m0 in axes:
            return self.low_pass_lines(plane, f)
        if m1 in axes:
            return self.low_pass_lines(plane.transpose(-1, -2), f).transpose(-1, -2)
        return plane

    def low_pass_lines(self, lines: Tensor, f: float) -> Tensor:
        """[..., L] lines at cutoff ``f``, with the field's boundary (periodic or mirror)."""
        if self.mirror_boundary:
            return fourier.mirrored(self.ops.filter_lines, lines, f, 1)
        return self.ops.filter_lines(lines, f)

    # -- preparation ----------------------------------------------------------------------------------------------
    def prepare(self, f_density: float, f_color: float) -> None:
        """Filter once for this iteration (or this render) and keep the result for every lookup.

        Without gradients (renders), a second call with the same cutoffs and unchanged parameters keeps what the
        first one made, so the views of one render share the filtering and any tables built from it.
        """
        key = (f_density, f_color, self._parameter_versions()) if not torch.is_grad_enabled() else None
        if key is not None and self._filtered is not None and self._render_key == key:
            return
        self._filtered = self.filter(f_density, f_color)
        self._render_key = key

    @contextmanager
    def filtered_at(self, f_density: float, f_color: float) -> Iterator[FilteredGrids]:
        """Evaluate the field at these cutoffs inside the block, then restore the previous filtering. The filtering is
        made without gradients (lookups in the block are as the caller's grad mode says).

        Why restore: the trainer may export between iterations, and its prepared (autograd) filtering must not
        silently become this one.
        """
        previous, previous_key = self._filtered, self._render_key
        try:
            with torch.no_grad():
                self.prepare(f_density, f_color)
            yield self.filtered
        finally:
            self._filtered, self._render_key = previous, previous_key

    @contextmanager
    def detached_filtering(self) -> Iterator[list[tuple[Tensor, Tensor]]]:
        """Inside the block, lookups and regularisers read leaf copies of this iteration's filtered factors, so that
        backward passes stop there (``pipelines.ray_chunks``); yields the (filtered factor, leaf copy) pairs whose
        leaves' gradients the block accumulates. A grid that stands for both keeps standing for both."""
        grids, pairs = self.filtered, []
        copies: dict[int, FilteredFactors] = {}

        def leaf(t: Tensor) -> Tensor:
            if not t.requires_grad:
                return t
            pairs.append((t, t.detach().requires_grad_()))
            return pairs[-1][1]

        def detached(factors: FilteredFactors) -> FilteredFactors:
            if id(factors) not in copies:
                planes, lines = [leaf(t) for t in factors.planes], [leaf(t) for t in factors.lines]
                copies[id(factors)] = FilteredFactors(planes, lines, factors.rendering)
            return copies[id(factors)]

        self._filtered = FilteredGrids(detached(grids.density), detached(grids.appearance), grids.cutoffs)
        try:
            yield pairs
        finally:
            self._filtered = grids

    def _parameter_versions(self) -> tuple:
        """Identity and in-place version of every parameter and buffer: any optimiser step or resize changes it."""
        return tuple((id(t), t._version) for t in (*self.parameters(), *self.buffers()))

    def invalidate(self) -> None:
        self._filtered = None
        self._render_key = None

    @property
    def filtered(self) -> FilteredGrids:
        if self._filtered is None:
            raise RuntimeError("field.prepare(...) must run before lookups (and after every resize)")
        return self._filtered

    def normalize(self, xyz: Tensor) -> Tensor:
        """World points to the grid's [-1, 1]³ (align_corners=True: the box corners are grid vertices)."""
        return (xyz - self.aabb[0]) * (2.0 / (self.aabb[1] - self.aabb[0])) - 1.0
