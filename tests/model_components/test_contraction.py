"""The scene contraction and the contracted sampler: identity inside the inner cube, a bijection onto (-2, 2)³ outside
it, and samples that march the contracted coordinate evenly from near to far."""

from __future__ import annotations

import torch

from fourierf_plugin.model_components.ray_sampling import (
    contract,
    contracted_arc_table,
    contracted_samples,
    uncontract,
)

BOX = torch.tensor([[-2.0] * 3, [2.0] * 3])


def test_contraction_keeps_the_inner_cube_and_squeezes_the_rest_into_the_shell() -> None:
    inner = torch.rand(1000, 3, generator=torch.Generator().manual_seed(0)) * 2 - 1
    assert torch.equal(contract(inner), inner)
    far = torch.randn(1000, 3, generator=torch.Generator().manual_seed(1)) * 1e3
    squeezed = contract(far)
    norm = squeezed.abs().amax(dim=-1)
    assert bool((norm > 1).all() and (norm < 2).all())
    torch.testing.assert_close(uncontract(squeezed), far, rtol=1e-3, atol=1e-3)  # float32 next to the face at 2
    face = torch.tensor([[1.0, 0.3, -0.2]])
    torch.testing.assert_close(contract(face * (1 + 1e-6)), face, atol=1e-5, rtol=0)  # continuous at the cube's face


def test_contraction_is_monotone_along_a_ray_from_the_centre() -> None:
    t = torch.linspace(0.0, 500.0, 2001).unsqueeze(-1)
    direction = torch.nn.functional.normalize(torch.tensor([[0.3, -0.8, 0.5]]), dim=-1)
    radius = contract(t * direction).norm(dim=-1)
    assert bool((radius[1:] > radius[:-1]).all())


def rays(n: int = 64, seed: int = 0) -> tuple[torch.Tensor, torch.Tensor]:
    g = torch.Generator().manual_seed(seed)
    origins = torch.rand(n, 3, generator=g) * 1.6 - 0.8  # cameras inside the inner cube
    directions = torch.nn.functional.normalize(torch.randn(n, 3, generator=g), dim=-1)
    return origins, directions


def test_contracted_samples_run_from_near_to_far_with_even_contracted_steps() -> None:
    origins, directions = rays()
    near, far, step = 0.05, 1000.0, 0.02
    samples = contracted_samples(origins, directions, BOX, near, far, step, 10_000)
    t, inside = samples.t, samples.inside
    assert bool((t[:, 1:] >= t[:, :-1]).all()) and float(t.min()) >= near - 1e-6 and float(t.max()) <= far * 1.0001
    assert bool(samples.points.abs().amax(dim=-1).le(2.0).all())
    # consecutive samples inside the ray's span lie about one step apart in the contracted grid
    gaps = (samples.points[:, 1:] - samples.points[:, :-1]).norm(dim=-1)[inside[:, 1:]]
    assert (
        float(gaps.quantile(0.99)) <= step * 1.05 and float(gaps.max()) <= 2 * step
    )  # the table's last cell is coarse
    span = contracted_arc_table(origins, directions, near, far)[1][:, -1]
    assert bool((inside.sum(dim=-1) >= (span / step).floor()).all())  # every ray marched to its end


def test_contracted_samples_inside_the_inner_cube_are_the_euclidean_ones() -> None:
    origins, directions = rays(seed=3)
    samples = contracted_samples(origins, directions, BOX, 0.05, 1000.0, 0.02, 10_000)
    before = samples.points.abs().amax(dim=-1) < 1.0
    metric = origins.unsqueeze(1) + directions.unsqueeze(1) * samples.t.unsqueeze(-1)
    torch.testing.assert_close(samples.points[before], metric[before], atol=1e-5, rtol=0)


def test_training_jitter_shifts_samples_within_one_step() -> None:
    origins, directions = rays(seed=5)
    plain = contracted_samples(origins, directions, BOX, 0.05, 1000.0, 0.05, 10_000)
    jittered = contracted_samples(
        origins, directions, BOX, 0.05, 1000.0, 0.05, 10_000, torch.Generator().manual_seed(1)
    )
    first = jittered.t[:, 0] - plain.t[:, 0]
    assert bool((first >= 0).all() and (first <= 0.05 + 1e-6).all())
    assert torch.isfinite(jittered.deltas).all() and bool((jittered.deltas >= 0).all())
