"""Checks of camera poses read from a dataset: a camera-to-world must rotate, not squash or mirror.

Why at parse time: a zero or singular matrix otherwise passes every shape check and ends in NaN rays, a crash in the
first training step far from the file that caused it.
"""

from __future__ import annotations

import numpy as np

ROTATION_TOLERANCE = 1e-2
"""How far R^T R may be from the identity (and det R from 1): room for rounded JSON, none for a scaled or zero R."""


def rotation_problem(c2w: np.ndarray) -> str | None:
    """Why the 3x3 rotation of a camera-to-world ([3, 4] or [4, 4]) is not a rotation, or None when it is one."""
    r = np.asarray(c2w, dtype=np.float64)[:3, :3]
    det = float(np.linalg.det(r))
    if abs(det) < 1e-9:
        return "its rotation is singular (a zero or degenerate matrix)"
    if det < 0:
        return f"its rotation mirrors (determinant {det:.3g})"
    error = float(np.abs(r.T @ r - np.eye(3)).max())
    if error > ROTATION_TOLERANCE or abs(det - 1.0) > ROTATION_TOLERANCE:
        return f"its rotation is not orthonormal (|R^T R - I| = {error:.3g}, determinant {det:.3g})"
    return None
