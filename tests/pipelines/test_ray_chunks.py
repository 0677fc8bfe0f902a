"""A batch taken in chunks trains as the whole batch does: same loss terms, same gradient on every parameter (to
rounding), for free factors, ZeroRF's generated ones (with its alpha term) and a forward-facing scene's NDC rays."""

from __future__ import annotations

import itertools
from pathlib import Path

import pytest
import torch

from fourierf_plugin.pipelines import base
from fourierf_plugin.pipelines.ray_chunks import chunk_spans, gradient_carrier, max_training_samples
from fourierf_plugin.scripts.train import build_config, parse_args
from tests.helpers import TINY_FLAGS, TINY_SCENE


@pytest.mark.parametrize(("rays", "per_ray", "cap"), [(1024, 443, 2**20), (16384, 700, 2**21), (7, 3, 5)])
def test_spans_cover_the_batch_in_chunks_within_the_cap(rays: int, per_ray: int, cap: int) -> None:
    spans = chunk_spans(rays, per_ray, cap)
    assert spans[0][0] == 0 and spans[-1][1] == rays
    assert all(a[1] == b[0] for a, b in itertools.pairwise(spans))
    sizes = [stop - start for start, stop in spans]
    assert max(sizes) * per_ray <= max(cap, per_ray)  # a single ray over the cap is its own chunk
    assert set(sizes[:-1]) <= {sizes[0]} and sizes[-1] <= sizes[0]  # equal chunks, the last one at most as large
    assert len(chunk_spans(rays, per_ray, rays * per_ray)) == 1  # a batch that fits is one pass


def test_the_carrier_is_zero_and_carries_the_given_gradients() -> None:
    a, b = torch.randn(3, requires_grad=True), torch.randn(2, 2, requires_grad=True)
    ga, gb = torch.randn(3), torch.randn(2, 2)
    carrier = gradient_carrier([(a * 2.0, ga), (b, gb)])
    assert carrier.item() == 0.0
    carrier.backward()
    torch.testing.assert_close(a.grad, 2.0 * ga)
    torch.testing.assert_close(b.grad, gb)


def _step(data: Path, out: Path, method: str, flags: list[str], chunks: int, monkeypatch) -> tuple[dict, dict]:
    """Loss terms and parameter gradients of step 0 of a tiny run, its batch in ``chunks`` chunks."""
    if chunks > 1:
        monkeypatch.setattr(base, "chunk_spans", lambda rays, per_ray, cap: chunk_spans(rays, 1, -(-rays // chunks)))
    args = [method, "--data", str(data), "--output-dir", str(out), "--max-num-iterations", "30", *TINY_FLAGS, *flags]
    config, _ = build_config(parse_args(args))
    torch.manual_seed(0)
    pipeline = config.pipeline.setup(
        device=torch.device("cpu"), max_iters=30, generator=torch.Generator().manual_seed(0)
    )
    loss, metrics = pipeline.train_step(0)
    loss.backward()
    grads = {name: p.grad.clone() for name, p in pipeline.model.named_parameters() if p.grad is not None}
    monkeypatch.undo()
    return {k: float(v) for k, v in metrics.items()}, grads


@pytest.mark.parametrize(
    ("method", "scene"),
    [("fourierf-vm", "lego"), ("zerorf-vm", "lego"), ("fourierf-vm", "llff")],
)
def test_chunks_give_the_whole_batch_gradient(method: str, scene: str, llff_scene: Path, tmp_path: Path, monkeypatch):
    data, flags = (TINY_SCENE, []) if scene == "lego" else (llff_scene, ["llff-data", "--num-views", "3"])
    if method == "zerorf-vm":
        flags = ["--pipeline.model.zerorf.plane-channels", "32", "32", *flags]
    whole, whole_grads = _step(data, tmp_path / "whole", method, flags, 1, monkeypatch)
    parts, part_grads = _step(data, tmp_path / "parts", method, flags, 3, monkeypatch)
    assert whole.keys() == parts.keys()
    for name, value in whole.items():
        assert parts[name] == pytest.approx(value, rel=1e-5, abs=1e-7), name
    assert whole_grads.keys() == part_grads.keys() and whole_grads
    for name, grad in whole_grads.items():
        torch.testing.assert_close(part_grads[name], grad, rtol=1e-4, atol=1e-7, msg=name)


def test_default_cpu_batches_fit_one_pass_and_zerorfs_latest_does_not() -> None:
    """On a 16 GB machine or larger: the default 1024-ray batch of the final CPU grid (192³ at most: under 700 samples
    a ray) is one pass; ZeroRF's 16384-ray stage over a forward-facing box (~350 samples a ray) is not."""
    cap = max_training_samples(torch.device("cpu"))
    if cap * 6e3 < 4 * 2**30:
        pytest.skip("a machine with less than 16 GB of memory chunks smaller batches")
    assert len(chunk_spans(1024, 700, cap)) == 1
    assert len(chunk_spans(16384, 346, cap)) > 1
