"""Training colour in checkpointed chunks (``checkpoint_above``): a memory saving that must not change the numbers."""

from __future__ import annotations

import torch

from tests.helpers import (
    rays_through_the_slab,
    single_torch_thread,  # noqa: F401 - autouse fixture
    slab_model,
)


def _train_forward(checkpoint_above: int) -> tuple[torch.Tensor, dict[str, torch.Tensor], list[int]]:
    model = slab_model(0.05, checkpoint_above=checkpoint_above, checkpoint_chunk=50)
    calls: list[int] = []
    rgb = model.field.rgb

    def counted(xyz: torch.Tensor, directions: torch.Tensor | None) -> torch.Tensor:
        calls.append(xyz.shape[0])
        return rgb(xyz, directions)

    model.field.rgb = counted  # type: ignore[method-assign]
    model.prepare(5)
    origins, directions = rays_through_the_slab(32)
    out = model(origins, directions, training=True)
    out["rgb"].square().sum().backward()
    grads = {n: p.grad.clone() for n, p in model.named_parameters() if p.grad is not None}
    return out["rgb"].detach(), grads, calls


def test_checkpointed_chunks_give_the_same_colours_and_gradients() -> None:
    rgb, grads, calls = _train_forward(checkpoint_above=0)
    shaded = calls[0]
    assert shaded > 120  # enough samples to be split below
    chunked_rgb, chunked_grads, chunked_calls = _train_forward(checkpoint_above=100)
    # Each 50-sample chunk runs twice: once forward, once recomputed in the backward pass.
    assert chunked_calls[: -(-shaded // 50)] == [50] * (shaded // 50) + ([shaded % 50] if shaded % 50 else [])
    assert len(chunked_calls) == 2 * -(-shaded // 50)
    torch.testing.assert_close(chunked_rgb, rgb, atol=0, rtol=0)
    assert grads.keys() == chunked_grads.keys() and any(k.startswith("field.decoder") for k in grads)
    for name, grad in grads.items():
        torch.testing.assert_close(chunked_grads[name], grad, atol=1e-7, rtol=1e-5, msg=name)


def test_few_shaded_samples_are_not_checkpointed() -> None:
    _, _, calls = _train_forward(checkpoint_above=10**6)
    assert len(calls) == 1  # one forward, nothing recomputed
