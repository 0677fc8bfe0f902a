"""The true surface of a scene: the reference points and distances that exported meshes are scored against."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from fourierf_plugin.synthetic.primitives import Primitive
from fourierf_plugin.synthetic.scene import SceneSpec


def sample_surface(spec: SceneSpec, n: int, seed: int = 0, occluders: Sequence[Primitive] = ()) -> np.ndarray:
    """[n, 3] points uniform (by area) on the scene's exposed surface: the union of the primitives' surfaces
    without the parts buried inside another solid. This is the reference surface of Chamfer distances.

    ``occluders`` are solids that bury surface without adding any of their own (the table under an object: the
    object's faces resting in it are not part of the object's exposed surface).

    Area-weighted sampling with rejection keeps the result uniform over what remains. Surfaces that no camera
    sees (undersides, the faces of a box resting on the ground) are kept: they are exposed, just unobserved.
    """
    if n < 0:
        raise ValueError(f"n must be >= 0, got {n}")
    rng = np.random.default_rng(seed)
    prims = spec.primitives
    areas = np.array([p.area() for p in prims])
    kept: list[np.ndarray] = []
    total = 0
    for _ in range(100):
        if total >= n:
            break
        m = max(2 * (n - total), 64)
        which = rng.choice(len(prims), size=m, p=areas / areas.sum())
        points = np.empty((m, 3))
        visible = np.ones(m, dtype=bool)
        for i, prim in enumerate(prims):
            mine = which == i
            points[mine] = prim.sample(int(mine.sum()), rng)
        for j, other in enumerate(prims):
            visible &= ~((which != j) & other.contains(points))
        for solid in occluders:
            visible &= ~solid.contains(points)
        kept.append(points[visible])
        total += int(visible.sum())
    if total < n:
        raise ValueError("the scene's surface is (almost) entirely buried inside its solids")
    return np.concatenate(kept)[:n] if kept else np.zeros((0, 3))


def surface_distance(spec: SceneSpec, points: np.ndarray) -> np.ndarray:
    """Unsigned distance [N] of each point to the nearest primitive surface (buried parts included)."""
    points = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    return np.min([p.surface_distance(points) for p in spec.primitives], axis=0)
