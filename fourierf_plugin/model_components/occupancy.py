"""Occupancy (alpha) grid: which cells may hold density, the AABB shrink, and the lookups that skip empty space.

TensoRF samples its alpha volume trilinearly and keeps points where the result is > 0, i.e. where any of the 8
surrounding vertices is on. We precompute that OR per cell once, so a lookup is one integer gather.
"""

from __future__ import annotations

import torch
import torch.nn.functional as F
from torch import Tensor, nn


def vertex_grid(aabb: Tensor, reso: list[int]) -> Tensor:
    """World positions [Rx, Ry, Rz, 3] of the grid vertices spanning ``aabb`` (corners included)."""
    axes = [torch.linspace(float(aabb[0, i]), float(aabb[1, i]), reso[i], device=aabb.device) for i in range(3)]
    return torch.stack(torch.meshgrid(*axes, indexing="ij"), dim=-1)


def occupancy_from_alpha(alpha: Tensor, threshold: float) -> Tensor:
    """Vertex mask [Rx, Ry, Rz]: alpha dilated by a 3³ max-pool, then ≥ threshold."""
    dilated = F.max_pool3d(alpha[None, None], kernel_size=3, stride=1, padding=1)[0, 0]
    return dilated >= threshold


def cells_from_vertices(vertices: Tensor) -> Tensor:
    """Cell mask [Rx-1, Ry-1, Rz-1]: a cell is on when any of its 8 corner vertices is on."""
    pooled = F.max_pool3d(vertices.float()[None, None], kernel_size=2, stride=1)[0, 0]
    return pooled > 0


def occupied_aabb(vertices: Tensor, aabb: Tensor) -> Tensor | None:
    """Tight box [2, 3] around the on vertices, or None when nothing is on."""
    idx = vertices.nonzero()
    if idx.numel() == 0:
        return None
    reso = torch.tensor(vertices.shape, device=aabb.device, dtype=aabb.dtype)
    units = (aabb[1] - aabb[0]) / (reso - 1)
    lo = aabb[0] + idx.amin(dim=0).to(aabb.dtype) * units
    hi = aabb[0] + idx.amax(dim=0).to(aabb.dtype) * units
    return torch.stack([lo, hi])


def shrink_bounds(new_aabb: Tensor, aabb: Tensor, reso: list[int]) -> tuple[list[int], list[int], Tensor]:
    """Vertex index ranges [lo, hi) covering ``new_aabb`` on the current grid, and the box those vertices span."""
    size = torch.tensor(reso, dtype=aabb.dtype, device=aabb.device)
    units = (aabb[1] - aabb[0]) / (size - 1)
    # lo ≤ R-2 so that the two-vertex minimum below still fits in the grid (a box on the far face would give hi = R+1).
    lo = torch.round((new_aabb[0] - aabb[0]) / units).long().clamp(min=0).minimum(size.long() - 2)
    hi = (torch.round((new_aabb[1] - aabb[0]) / units).long() + 1).minimum(size.long())
    hi = torch.maximum(hi, lo + 2)  # keep at least two vertices per axis
    lo_r = lo.to(aabb.dtype) / (size - 1)
    hi_r = (hi - 1).to(aabb.dtype) / (size - 1)
    box = torch.stack([(1 - lo_r) * aabb[0] + lo_r * aabb[1], (1 - hi_r) * aabb[0] + hi_r * aabb[1]])
    return lo.tolist(), hi.tolist(), box


class OccupancyGrid(nn.Module):
    """Cell occupancy over its own box; before the first update everything counts as occupied."""

    def __init__(self) -> None:
        super().__init__()
        self.register_buffer("cells", torch.zeros(0, 0, 0, dtype=torch.bool))
        self.register_buffer("aabb", torch.zeros(2, 3))
        self._bounds: tuple[tuple, list[float], list[float]] | None = None  # (key, lo, hi) of ``aabb`` on the host

    @property
    def active(self) -> bool:
        return self.cells.numel() > 0

    def set(self, vertices: Tensor, aabb: Tensor) -> None:
        self.cells = cells_from_vertices(vertices)
        self.aabb = aabb.detach().clone()

    def query(self, xyz: Tensor) -> Tensor:
        """Bool [N]: the point lies in an occupied cell (always True before the first update).

        Axis by axis on [N] columns: one pass each for position, bounds and index, ~3x faster on CPU than the same
        arithmetic on [N, 3] rows, whose per-row reductions and int64 index products dominate a render's marching.
        """
        if not self.active:
            return torch.ones(xyz.shape[0], dtype=torch.bool, device=xyz.device)
        shape = self.cells.shape
        lo, hi = self._host_bounds()
        inside: Tensor | None = None
        flat: Tensor | None = None
        for axis, cells in enumerate(shape):
            pos = (xyz[:, axis] - lo[axis]) * (cells / (hi[axis] - lo[axis]))
            ok = (pos >= 0) & (pos <= cells)
            index = pos.clamp(0, cells - 1).int()  # the far face belongs to the last cell
            inside = ok if inside is None else inside & ok
            flat = index if flat is None else flat * cells + index
        assert inside is not None and flat is not None
        return inside & self.cells.reshape(-1).index_select(0, flat)

    def _host_bounds(self) -> tuple[list[float], list[float]]:
        """The box corners as Python floats, read from the device once per box (not once per query)."""
        key = (id(self.aabb), self.aabb._version)
        if self._bounds is None or self._bounds[0] != key:
            self._bounds = (key, self.aabb[0].tolist(), self.aabb[1].tolist())
        return self._bounds[1], self._bounds[2]
