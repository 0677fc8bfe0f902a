"""A training batch too large to evaluate in one pass, taken in chunks with the whole batch's gradient.

Why: memory grows with the samples a step evaluates (rays × samples per ray), and ZeroRF's ray schedule reaches 16
times the first batch; on a forward-facing scene, where every ray crosses the whole box, one pass over such a batch
does not fit a workstation's memory. Each chunk's loss is back-propagated at once into detached copies of the
iteration's filtered factors (and into the parameters it reads directly), so a chunk's activations are freed before
the next; one backward through the filtering (and ZeroRF's generators) then delivers what the chunks accumulated.
The result is the batch's gradient to rounding: every loss term is a mean over the batch's rays or does not depend on
them, so the chunks' terms weighted by their share of the rays sum to the batch's.
"""

from __future__ import annotations

import math
import os
from collections.abc import Iterable
from typing import TYPE_CHECKING

import torch
from torch import Tensor

from fourierf_plugin.utils.phases import phase

if TYPE_CHECKING:
    from fourierf_plugin.data.datamanager import RayBatch
    from fourierf_plugin.models.fourierf import FourieRFModel

MEMORY_SHARE = 0.25
"""The share of the device's memory one training pass's samples may take."""
BYTES_PER_TRAINING_SAMPLE = 6e3
"""Memory a training sample holds for its backward pass, forward-facing ZeroRF (the heaviest field here) on a CPU:
the estimate ``max_training_samples`` divides by, generous for the other fields."""


def device_memory_bytes(device: torch.device) -> int:
    """The memory of ``device``: a CUDA card's own, else the machine's RAM (a CPU's, or memory shared with the GPU)."""
    if device.type == "cuda":
        return int(torch.cuda.get_device_properties(device).total_memory)
    return os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES")


def max_training_samples(device: torch.device) -> int:
    """The samples (rays × samples per ray) one training pass on ``device`` evaluates at most: every default batch
    of the built-in presets on a workstation, but not ZeroRF's later ones on a CPU."""
    return max(1, int(device_memory_bytes(device) * MEMORY_SHARE / BYTES_PER_TRAINING_SAMPLE))


def chunk_spans(rays: int, samples_per_ray: int, max_samples: int) -> list[tuple[int, int]]:
    """[start, stop) ray ranges of as few equal chunks as keep each within ``max_samples`` samples (one span when the
    whole batch fits)."""
    per_chunk = max(1, max_samples // max(1, samples_per_ray))
    count = math.ceil(rays / per_chunk)
    size = math.ceil(rays / max(1, count))
    return [(start, min(rays, start + size)) for start in range(0, rays, size)] or [(0, 0)]


def gradient_carrier(pairs: Iterable[tuple[Tensor, Tensor]]) -> Tensor:
    """A zero whose gradient with respect to each tensor ``t`` of the pairs ``(t, g)`` is ``g``: one backward from it
    delivers gradients computed earlier."""
    total = sum(((t * g).sum() for t, g in pairs), torch.zeros(()))
    return total - total.detach()


def accumulate_in_chunks(
    model: FourieRFModel, batch: RayBatch, step: int, spans: list[tuple[int, int]]
) -> tuple[dict[str, Tensor], Tensor]:
    """The batch's loss terms (values, without a graph) and the carrier of their gradient, evaluated chunk by chunk
    over ``spans`` of its rays (``model.prepare(step)`` has run). Gradients the parameters held before are dropped:
    a step's gradients are the trainer's to make."""
    parameters = list(model.parameters())
    for p in parameters:
        p.grad = None
    total = batch.origins.shape[0]
    background = model.draw_background(total, batch.origins.device)  # the batch's, not one per chunk
    terms: dict[str, Tensor] = {}
    with model.field.detached_filtering() as factor_pairs:
        for start, stop in spans:
            share = (stop - start) / total
            chunk_background = background if background.dim() == 1 else background[start:stop]
            outputs = model(batch.origins[start:stop], batch.directions[start:stop], chunk_background)
            with phase("losses"):
                chunk_terms = model.loss_dict(outputs, batch.rgba[start:stop], step)
                chunk_loss = torch.stack(list(chunk_terms.values())).sum() * share
            with phase("backward"):
                chunk_loss.backward(retain_graph=True)  # the leaves' derived tables serve every chunk
            for name, value in chunk_terms.items():
                terms[name] = terms.get(name, 0.0) + value.detach() * share
        pairs = [(t, leaf.grad) for t, leaf in factor_pairs if leaf.grad is not None]
    pairs += [(p, p.grad) for p in parameters if p.grad is not None]
    for p in parameters:
        p.grad = None
    return terms, gradient_carrier(pairs).to(batch.origins.device)
