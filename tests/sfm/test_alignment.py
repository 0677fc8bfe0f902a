"""Similarity alignment (Umeyama) and pose errors after it."""

from __future__ import annotations

import numpy as np
import pytest

from fourierf_plugin.sfm.alignment import pose_errors, rotation_angle_deg, umeyama


def _random_rotation(rng: np.random.Generator) -> np.ndarray:
    q, r = np.linalg.qr(rng.normal(size=(3, 3)))
    q = q * np.sign(np.diag(r))
    return q * np.sign(np.linalg.det(q))


def _axis_angle(axis: np.ndarray, degrees: float) -> np.ndarray:
    axis = axis / np.linalg.norm(axis)
    k = np.array([[0, -axis[2], axis[1]], [axis[2], 0, -axis[0]], [-axis[1], axis[0], 0]])
    a = np.radians(degrees)
    return np.eye(3) + np.sin(a) * k + (1 - np.cos(a)) * k @ k


@pytest.mark.parametrize("seed", range(5))
def test_umeyama_recovers_a_known_similarity(seed: int) -> None:
    rng = np.random.default_rng(seed)
    source = rng.normal(size=(12, 3))
    rotation, scale, translation = _random_rotation(rng), float(rng.uniform(0.1, 10)), rng.normal(size=3) * 5
    sim = umeyama(source, scale * source @ rotation.T + translation)
    np.testing.assert_allclose(sim.rotation, rotation, atol=1e-10)
    assert sim.scale == pytest.approx(scale)
    np.testing.assert_allclose(sim.translation, translation, atol=1e-9)
    assert np.linalg.det(sim.rotation) == pytest.approx(1.0)


def test_umeyama_never_returns_a_reflection() -> None:
    rng = np.random.default_rng(0)
    source = rng.normal(size=(10, 3))
    mirrored = source * [1, 1, -1]  # no rotation maps these exactly: the best proper one must still be a rotation
    sim = umeyama(source, mirrored)
    assert np.linalg.det(sim.rotation) == pytest.approx(1.0)
    np.testing.assert_allclose(sim.rotation @ sim.rotation.T, np.eye(3), atol=1e-12)


def test_umeyama_is_least_squares_under_noise() -> None:
    rng = np.random.default_rng(1)
    source = rng.normal(size=(200, 3))
    rotation = _random_rotation(rng)
    target = 2.0 * source @ rotation.T + 1.0 + rng.normal(scale=0.01, size=source.shape)
    sim = umeyama(source, target)
    assert rotation_angle_deg(sim.rotation, rotation) < 0.1
    assert sim.scale == pytest.approx(2.0, rel=1e-2)
    residual = np.linalg.norm(sim.apply(source) - target, axis=1)
    assert residual.mean() < 0.03


def test_umeyama_rejects_degenerate_input() -> None:
    with pytest.raises(ValueError, match="at least 3"):
        umeyama(np.zeros((2, 3)), np.zeros((2, 3)))
    line = np.outer(np.arange(5.0), [1.0, 2.0, 3.0])
    with pytest.raises(ValueError, match="one line"):
        umeyama(line, line)
    with pytest.raises(ValueError, match="same shape"):
        umeyama(np.zeros((4, 3)), np.zeros((5, 3)))


def test_pose_errors_see_only_what_a_similarity_cannot_explain() -> None:
    rng = np.random.default_rng(2)
    reference = np.tile(np.eye(4), (6, 1, 1))
    for c2w in reference:
        c2w[:3, :3] = _random_rotation(rng)
        c2w[:3, 3] = rng.normal(size=3) * 3
    world = np.eye(4)
    world[:3, :3] = 0.5 * _random_rotation(rng)
    world[:3, 3] = [4.0, -1.0, 2.0]
    estimated = world @ reference  # the same cameras in another frame, at half the scale
    estimated[:, :3, :3] /= 0.5
    errors = pose_errors(estimated, reference)
    np.testing.assert_allclose(errors.rotation_deg, 0.0, atol=1e-5)
    np.testing.assert_allclose(errors.centre_error, 0.0, atol=1e-9)
    assert errors.similarity.scale == pytest.approx(2.0)

    tilted = estimated.copy()
    tilted[3, :3, :3] = tilted[3, :3, :3] @ _axis_angle(np.array([1.0, 1.0, 0.0]), 2.0)
    errors = pose_errors(tilted, reference)
    assert errors.rotation_deg[3] == pytest.approx(2.0, abs=1e-6)
    np.testing.assert_allclose(np.delete(errors.rotation_deg, 3), 0.0, atol=1e-5)
    extent = max(np.linalg.norm(a - b) for a in reference[:, :3, 3] for b in reference[:, :3, 3])
    assert errors.reference_extent == pytest.approx(extent)
