"""TensoRF factorisations (VM = planes x lines, CP = lines only) with per-axis resolutions.

Storage layout: plane i pairs axes ``MAT_MODES[i] = (m0, m1)`` and is stored [C, R[m1], R[m0]] so that
``grid_sample`` reads it at (x̂_m0, x̂_m1); line i runs along ``VEC_MODES[i]`` and is stored [C, R[v]]. Raw parameters
are what the optimiser updates; lookups always go through a (possibly Fourier-filtered) copy passed in explicitly,
which keeps the filtering in one place and the lookups pure.

How a factor is read at a point is a ``FactorLookup``: here the reference, ``grid_sample`` (bilinear, corners aligned,
border-clamped); ``fourierf_plugin.accel.lookups`` reads the same values with cheaper gathers.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any, Protocol

import torch
import torch.nn.functional as F
from torch import Tensor, nn

MAT_MODES: tuple[tuple[int, int], ...] = ((0, 1), (0, 2), (1, 2))
VEC_MODES: tuple[int, ...] = (2, 1, 0)


def interp_plane(plane: Tensor, u: Tensor, v: Tensor) -> Tensor:
    """Bilinear lookup of a [C, H, W] plane at normalised (u→W, v→H) in [-1, 1] (align_corners=True), -> [N, C].

    Returns the stored values exactly at grid vertices; points outside the box read the border.
    """
    grid = torch.stack([u, v], dim=-1).view(1, -1, 1, 2)
    out = F.grid_sample(plane.unsqueeze(0), grid, mode="bilinear", align_corners=True, padding_mode="border")
    return out.view(plane.shape[0], -1).T


def interp_lines(line: Tensor, coord: Tensor) -> Tensor:
    """Linear interpolation of a [C, L] line at normalised coords in [-1, 1] (align_corners=True), -> [N, C]."""
    return interp_plane(line.unsqueeze(-1), torch.zeros_like(coord), coord)


class FactorLookup(Protocol):
    """Reads factors at normalised coordinates; ``factor`` is a filtered plane/line or a lookup's own copy of it."""

    def plane(self, plane: Any, u: Tensor, v: Tensor) -> Tensor: ...

    def line(self, line: Any, coord: Tensor) -> Tensor: ...


class GridSampleLookup:
    """The reference ``FactorLookup``: ``interp_plane`` and ``interp_lines``."""

    def plane(self, plane: Tensor, u: Tensor, v: Tensor) -> Tensor:
        return interp_plane(plane, u, v)

    def line(self, line: Tensor, coord: Tensor) -> Tensor:
        return interp_lines(line, coord)


GRID_SAMPLE = GridSampleLookup()


class TensorGrid(nn.Module):
    """Common state of the two factorisations: the raw parameters and their resizing."""

    planes: nn.ParameterList
    lines: nn.ParameterList
    plane_axes: tuple[tuple[int, int], ...] = MAT_MODES
    line_axes: tuple[int, ...] = VEC_MODES

    def __init__(self) -> None:
        super().__init__()
        self.planes = nn.ParameterList()
        self.lines = nn.ParameterList()

    @property
    def resolution(self) -> list[int]:
        """Per-axis vertex counts, read back from the line lengths."""
        reso = [0, 0, 0]
        for line, axis in zip(self.lines, self.line_axes, strict=True):
            reso[axis] = int(line.shape[-1])
        return reso

    def features(
        self, planes: Sequence[Any], lines: Sequence[Any], xyz: Tensor, lookup: FactorLookup = GRID_SAMPLE
    ) -> list[Tensor]:
        """Per-component features [N, C_i] for each factor group, from the given (filtered) factors."""
        raise NotImplementedError

    # -- resizing (applied to raw parameters) -----------------------------------------------------------------
    @torch.no_grad()
    def replace(self, planes: Sequence[Tensor], lines: Sequence[Tensor]) -> None:
        """Swap in new tensors (any shape) as fresh parameters, e.g. after an upsample or shrink."""
        for i, p in enumerate(planes):
            self.planes[i] = nn.Parameter(p.detach().clone().contiguous())
        for i, line in enumerate(lines):
            self.lines[i] = nn.Parameter(line.detach().clone().contiguous())

    def upsampled(self, planes: Sequence[Tensor], lines: Sequence[Tensor], reso: Sequence[int]) -> tuple[list, list]:
        """Bilinear/linear resize (align_corners=True) of the given tensors to per-axis ``reso``."""
        new_planes = [
            F.interpolate(p.unsqueeze(0), size=(reso[m1], reso[m0]), mode="bilinear", align_corners=True)[0]
            for p, (m0, m1) in zip(planes, self.plane_axes, strict=True)
        ]
        new_lines = [
            F.interpolate(line.unsqueeze(0), size=reso[a], mode="linear", align_corners=True)[0]
            for line, a in zip(lines, self.line_axes, strict=True)
        ]
        return new_planes, new_lines

    def cropped(self, lo: Sequence[int], hi: Sequence[int]) -> tuple[list, list]:
        """Raw tensors cropped to vertex index ranges [lo, hi) per axis (the AABB shrink)."""
        new_planes = [
            p[:, lo[m1] : hi[m1], lo[m0] : hi[m0]] for p, (m0, m1) in zip(self.planes, self.plane_axes, strict=True)
        ]
        new_lines = [line[:, lo[a] : hi[a]] for line, a in zip(self.lines, self.line_axes, strict=True)]
        return new_planes, new_lines


class TensorVM(TensorGrid):
    """Vector-matrix split: component c of group i is ``P_i[c](x_m0, x_m1) · L_i[c](x_v)``."""

    def __init__(self, reso: Sequence[int], components: Sequence[int], init_scale: float, generator: torch.Generator):
        super().__init__()
        if len(components) != 3:
            raise ValueError(f"VM needs 3 component counts (one per plane), got {components}")
        for c, (m0, m1), v in zip(components, MAT_MODES, VEC_MODES, strict=True):
            self.planes.append(nn.Parameter(init_scale * torch.randn(c, reso[m1], reso[m0], generator=generator)))
            self.lines.append(nn.Parameter(init_scale * torch.randn(c, reso[v], generator=generator)))

    def features(
        self, planes: Sequence[Any], lines: Sequence[Any], xyz: Tensor, lookup: FactorLookup = GRID_SAMPLE
    ) -> list[Tensor]:
        return vm_features(planes, lines, xyz, lookup)


def vm_features(planes: Sequence[Any], lines: Sequence[Any], xyz: Tensor, lookup: FactorLookup = GRID_SAMPLE) -> list:
    """Per-component features [N, C] of each plane × line group at normalised points: ``P_i(x_m0, x_m1) · L_i(x_v)``
    (free VM factors and generated ones are read alike)."""
    return [
        lookup.plane(p, xyz[:, m0], xyz[:, m1]) * lookup.line(line, xyz[:, v])
        for p, line, (m0, m1), v in zip(planes, lines, MAT_MODES, VEC_MODES, strict=True)
    ]


class TensorCP(TensorGrid):
    """CP: component c is ``L_x[c](x) · L_y[c](y) · L_z[c](z)``; there are no planes."""

    line_axes = (0, 1, 2)
    plane_axes = ()

    def __init__(self, reso: Sequence[int], components: Sequence[int], init_scale: float, generator: torch.Generator):
        super().__init__()
        if len(set(components)) != 1:
            raise ValueError(f"CP uses one component count for all three lines, got {components}")
        c = components[0]
        for axis in range(3):
            self.lines.append(nn.Parameter(init_scale * torch.randn(c, reso[axis], generator=generator)))

    def features(
        self, planes: Sequence[Any], lines: Sequence[Any], xyz: Tensor, lookup: FactorLookup = GRID_SAMPLE
    ) -> list[Tensor]:
        out = lookup.line(lines[0], xyz[:, 0])
        for axis in (1, 2):
            out = out * lookup.line(lines[axis], xyz[:, axis])
        return [out]
