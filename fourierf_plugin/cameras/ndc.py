"""Normalised device coordinates for forward-facing scenes (LLFF): the frustum beyond the near plane maps to a box.

The ray is first moved to the near plane (z = -near), then x, y are divided by depth and z maps to 1 + 2 near / z,
so the ray parameter t ∈ [0, 1] covers near plane → infinity with z_ndc = -1 + 2t.
"""

from __future__ import annotations

import torch
from torch import Tensor


def ndc_rays(
    origins: Tensor, directions: Tensor, focal: float, width: int, height: int, near: float = 1.0
) -> tuple[Tensor, Tensor]:
    """World rays [R, 3] (OpenGL, looking down -z, directions NOT normalised) -> NDC origins and directions."""
    t0 = -(near + origins[:, 2]) / directions[:, 2]
    o = origins + t0.unsqueeze(-1) * directions
    ox, oy, oz = o.unbind(-1)
    dx, dy, dz = directions.unbind(-1)
    ax, ay = -2.0 * focal / width, -2.0 * focal / height
    o_ndc = torch.stack([ax * ox / oz, ay * oy / oz, 1.0 + 2.0 * near / oz], dim=-1)
    d_ndc = torch.stack([ax * (dx / dz - ox / oz), ay * (dy / dz - oy / oz), -2.0 * near / oz], dim=-1)
    return o_ndc, d_ndc
