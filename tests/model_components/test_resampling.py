"""Coarse-to-fine sampling (``model_components.resampling``): stratified edges, the blurred histogram and the inverse
CDF against hand-computed values, and the invariants a second level relies on (sorted, inside its bins, mass where
the weights are)."""

from __future__ import annotations

import pytest
import torch

from fourierf_plugin.model_components.resampling import (
    blurred_weights,
    midpoints_and_lengths,
    sample_histogram,
    stratified_edges,
)

CPU = torch.device("cpu")


def test_render_edges_are_even_and_training_edges_stay_in_their_strata_and_sorted() -> None:
    even = stratified_edges(2.0, 6.0, 3, 5, None, CPU)
    torch.testing.assert_close(even, torch.tensor([[2.0, 3.0, 4.0, 5.0, 6.0]]).repeat(3, 1))
    drawn = stratified_edges(2.0, 6.0, 500, 5, torch.Generator().manual_seed(0), CPU)
    lower = torch.tensor([2.0, 2.5, 3.5, 4.5, 5.5])
    upper = torch.tensor([2.5, 3.5, 4.5, 5.5, 6.0])
    assert ((drawn >= lower) & (drawn <= upper)).all()
    assert (drawn[:, 1:] >= drawn[:, :-1]).all()
    assert drawn.std(dim=0).min() > 0.05, "each edge is jittered"


def test_the_histogram_widens_each_weight_to_its_neighbours_and_pads() -> None:
    weights = torch.tensor([[0.0, 1.0, 0.0, 0.0]])
    # padded [0, 0, 1, 0, 0, 0] -> two-tap max [0, 1, 1, 0, 0] -> two-tap mean [0.5, 1, 0.5, 0]
    torch.testing.assert_close(blurred_weights(weights, 0.01), torch.tensor([[0.51, 1.01, 0.51, 0.01]]))


def test_even_weights_give_the_inverse_of_a_uniform_cdf() -> None:
    edges = torch.tensor([[0.0, 1.0, 2.0, 3.0, 4.0]])
    got = sample_histogram(edges, torch.ones(1, 4), 5, None)
    torch.testing.assert_close(got, 4.0 * torch.linspace(0.0, 1.0 - 1e-6, 5).unsqueeze(0))


def test_all_the_mass_in_one_bin_puts_every_sample_inside_it() -> None:
    edges = torch.tensor([[0.0, 1.0, 2.0, 3.0, 4.0]]).repeat(64, 1)
    weights = torch.tensor([[0.0, 1.0, 0.0, 0.0]]).repeat(64, 1)
    for generator in (None, torch.Generator().manual_seed(1)):
        got = sample_histogram(edges, weights, 17, generator)
        assert ((got >= 1.0) & (got <= 2.0)).all()
        assert (got[:, 1:] >= got[:, :-1]).all()


def test_stratified_draws_split_the_samples_as_the_weights_do() -> None:
    """One draw per stratum: with weights 1 : 3 on two bins, 100 of 400 samples fall in the first (to within one)."""
    edges = torch.tensor([[0.0, 1.0, 2.0]]).repeat(8, 1)
    weights = torch.tensor([[1.0, 3.0]]).repeat(8, 1)
    got = sample_histogram(edges, weights, 400, torch.Generator().manual_seed(2))
    first = (got < 1.0).sum(dim=-1)
    assert ((first - 100).abs() <= 1).all()
    assert (got[:, 1:] >= got[:, :-1]).all() and got.min() >= 0.0 and got.max() <= 2.0


@pytest.mark.parametrize("generator", [None, torch.Generator().manual_seed(3)])
def test_uneven_edges_and_random_weights_give_sorted_samples_inside_the_span(generator) -> None:
    edges = torch.sort(torch.rand(32, 9, generator=torch.Generator().manual_seed(4)) * 5.0, dim=-1).values
    weights = torch.rand(32, 8, generator=torch.Generator().manual_seed(5))
    got = sample_histogram(edges, weights, 33, generator)
    assert got.shape == (32, 33)
    assert (got[:, 1:] >= got[:, :-1]).all()
    assert (got >= edges[:, :1]).all() and (got <= edges[:, -1:]).all()


def test_zero_weights_stay_finite() -> None:
    edges = torch.tensor([[0.0, 1.0, 2.0]])
    got = sample_histogram(edges, torch.zeros(1, 2), 4, None)
    assert torch.isfinite(got).all() and (got >= 0.0).all() and (got <= 2.0).all()


def test_midpoints_and_lengths_of_the_intervals() -> None:
    mids, lengths = midpoints_and_lengths(torch.tensor([[0.0, 1.0, 3.0]]))
    torch.testing.assert_close(mids, torch.tensor([[0.5, 2.0]]))
    torch.testing.assert_close(lengths, torch.tensor([[1.0, 2.0]]))
