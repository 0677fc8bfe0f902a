"""The sync counter itself: what it counts must not depend on which ids the allocator hands out."""

from __future__ import annotations

import torch

from tests.engine.sync_counter import SyncCounter


def test_a_host_tensor_moved_to_the_device_is_counted() -> None:
    with SyncCounter() as counter:
        torch.tensor([1.0]).to(torch.float64)
    assert counter.calls["host -> device (to)"] == 1


def test_a_device_tensor_that_reuses_a_dead_host_tensors_id_is_not_counted() -> None:
    """The flake this guards: a per-batch coin drawn on the host dies at once, and a later device tensor that gets
    its id was counted as a host copy when moved. CPython reuses ids only when the allocator happens to, so the reuse
    is forced: the dead host tensor's record is filed under the device tensor's id, as a reuse would file it."""
    with SyncCounter() as counter:
        host = torch.tensor([1.0])
        record = counter._host[id(host)]
        del host
        assert record() is None, "the host tensor should be dead once its last reference is gone"
        device = torch.zeros(1)
        counter._host[id(device)] = record
        device.to(torch.float64)
    assert counter.calls["host -> device (to)"] == 0, dict(counter.calls)
