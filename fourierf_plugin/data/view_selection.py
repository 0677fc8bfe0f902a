"""Which training views a few-shot run sees: a seeded k-means pick, or ids the user names.

The ZeroRF/FourieRF protocol clusters the training camera centres and keeps the view nearest each cluster
centre. sklearn's KMeans depends on the global RNG and its version, and two centres can share a nearest view;
this numpy version is fixed by its seed and never returns a view twice.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from fourierf_plugin.utils.errors import fail


def _sq_dists(points: np.ndarray, centres: np.ndarray) -> np.ndarray:
    """Squared distances [P, K], clamped at 0 against cancellation."""
    d = (points**2).sum(1)[:, None] - 2.0 * points @ centres.T + (centres**2).sum(1)[None, :]
    return np.maximum(d, 0.0)


def _kmeans_pp(points: np.ndarray, n: int, rng: np.random.Generator) -> np.ndarray:
    """k-means++ seeding: each next centre drawn with probability proportional to its squared distance."""
    centres = [points[rng.integers(len(points))]]
    closest = _sq_dists(points, centres[0][None])[:, 0]
    for _ in range(1, n):
        total = closest.sum()
        # All points already coincide with a centre (duplicated cameras): any point will do.
        probs = closest / total if total > 0 else np.full(len(points), 1.0 / len(points))
        centres.append(points[rng.choice(len(points), p=probs)])
        closest = np.minimum(closest, _sq_dists(points, centres[-1][None])[:, 0])
    return np.stack(centres)


def _lloyd(points: np.ndarray, centres: np.ndarray, max_iter: int, tol: float) -> tuple[np.ndarray, float]:
    """Lloyd iterations from ``centres``; returns (centres, inertia)."""
    for _ in range(max_iter):
        d = _sq_dists(points, centres)
        labels = d.argmin(1)
        new = centres.copy()
        worst_served = iter(np.argsort(-d[np.arange(len(points)), labels], kind="stable"))
        for k in range(len(centres)):
            members = points[labels == k]
            # An empty cluster moves onto the point worst served by the others.
            new[k] = members.mean(0) if len(members) else points[next(worst_served)]
        shift = ((new - centres) ** 2).sum()
        centres = new
        if shift <= tol:
            break
    d = _sq_dists(points, centres)
    return centres, float(d.min(1).sum())


def _nearest_distinct(points: np.ndarray, centres: np.ndarray) -> list[int]:
    """One distinct point per centre: closest (centre, point) pairs first, each point used once.

    A centre whose nearest point is taken gets its nearest untaken one.
    """
    d = _sq_dists(points, centres)  # [P, K]
    order = np.argsort(d, axis=None, kind="stable")
    taken_points: set[int] = set()
    chosen: dict[int, int] = {}
    for flat in order:
        p, k = divmod(int(flat), len(centres))
        if p in taken_points or k in chosen:
            continue
        chosen[k] = p
        taken_points.add(p)
        if len(chosen) == len(centres):
            break
    return sorted(chosen.values())


def kmeans_views(centers: np.ndarray, n: int, seed: int = 0, n_init: int = 10, max_iter: int = 300) -> list[int]:
    """Indices (ascending, distinct) of ``n`` views spread over the camera centres [N, 3] by seeded k-means."""
    points = np.asarray(centers, dtype=np.float64)
    if points.ndim != 2 or len(points) == 0:
        raise ValueError(f"centers must be a non-empty [N, D] array, got shape {points.shape}")
    if not 1 <= n <= len(points):
        raise ValueError(f"cannot pick {n} views from {len(points)}: need 1 <= n <= {len(points)}")
    if n_init < 1 or max_iter < 1:
        raise ValueError(f"n_init and max_iter must be >= 1, got {n_init} and {max_iter}")
    if n == len(points):
        return list(range(n))
    rng = np.random.default_rng(seed)
    tol = 1e-4 * float(points.var(0).mean())  # sklearn's tolerance: relative to the data's spread
    best_centres, best_inertia = None, np.inf
    for _ in range(n_init):
        centres, inertia = _lloyd(points, _kmeans_pp(points, n, rng), max_iter, tol)
        if inertia < best_inertia:
            best_centres, best_inertia = centres, inertia
    assert best_centres is not None
    return _nearest_distinct(points, best_centres)


def explicit_views(ids: Sequence[int], num_available: int, source: str) -> list[int]:
    """Validate user-given view ids (range, duplicates) against a split of ``num_available`` views."""
    ids = [int(i) for i in ids]
    valid = f"ids in 0..{num_available - 1} (frame indices in {source})"
    if not ids:
        fail(f"no view ids were given for {source}", f"pass at least one of the {valid}")
    bad = [i for i in ids if not 0 <= i < num_available]
    if bad:
        fail(f"view ids {bad} are out of range for {source}, which has {num_available} frames", f"use {valid}")
    dupes = sorted({i for i in ids if ids.count(i) > 1})
    if dupes:
        fail(f"view ids {dupes} are given more than once for {source}", f"list each view once, using {valid}")
    return ids


def regnerf_views(num_train: int, n: int) -> list[int]:
    """Positions in the training list picked by the RegNeRF/FreeNeRF rule: round-half-even of linspace(0, T-1, n)."""
    if not 1 <= n <= num_train:
        raise ValueError(f"cannot pick {n} of {num_train} training views")
    return [int(i) for i in np.round(np.linspace(0, num_train - 1, n))]


def validation_views(train: Sequence[int], chosen: Sequence[int], test: Sequence[int], count: int) -> list[int]:
    """Few-shot runs validate on training images they do not train on, so tuning never sees the test views:
    ``count`` of the unused ones, evenly spaced (RegNeRF's rule); with every training image in use, the test views."""
    in_use = set(chosen)
    unused = [i for i in train if i not in in_use]
    if not unused:
        return list(test)
    return [unused[j] for j in regnerf_views(len(unused), min(count, len(unused)))]


def check_view_counts(num_views: int | None, val_views: int) -> None:
    """The few-shot and validation view counts a parser takes (a clear error for impossible ones)."""
    if num_views is not None and num_views < 1:
        fail(f"--num-views must be >= 1, got {num_views}", "omit it to train on every training image")
    if val_views < 1:
        fail(f"--val-views must be >= 1, got {val_views}", "3 is the default")
