"""Counts what would make the host wait for a GPU, by watching every torch call of a block on the CPU.

A CUDA step stalls the host when it reads a device value (``item``, ``tolist``, ``bool``/``float``/``int`` of a
tensor, ``numpy``, ``cpu``), when an op's output shape depends on device data (``nonzero``, boolean indexing,
``unique``, ``masked_select``...), and when host data is copied to the device (a tensor built from Python or host
data, then moved). On a CPU none of these costs anything, so they are counted by name: tensors born on the host
(from Python data, or drawn from a host generator) are tracked, and reading them is free while moving them is not.
"""

from __future__ import annotations

import weakref
from collections import Counter

import torch
from torch.overrides import TorchFunctionMode

READS = {"item", "tolist", "__bool__", "__float__", "__int__", "__index__", "numpy", "cpu"}
DATA_DEPENDENT = {"nonzero", "argwhere", "unique", "unique_consecutive", "masked_select", "repeat_interleave"}
FROM_HOST = {"tensor", "as_tensor", "from_numpy"}
RANDOM = {"rand", "randn", "randint", "randperm", "rand_like", "randn_like", "bernoulli", "normal", "multinomial"}


class SyncCounter(TorchFunctionMode):
    """``with SyncCounter(device_generator) as c: ...`` then ``c.total`` / ``c.calls``.

    ``device_generator`` is the generator that lives on the (emulated) device: draws from any other generator are
    host draws.
    """

    def __init__(self, device_generator: torch.Generator | None = None) -> None:
        super().__init__()
        self.device_generator = device_generator
        self.calls: Counter[str] = Counter()
        # host-born tensors alive in the block, by id; the weak reference tells a live one from a later tensor that
        # reuses a dead one's id (a per-batch coin drawn on the host dies at once: its id is soon a device tensor's)
        self._host: dict[int, weakref.ref[torch.Tensor]] = {}

    @property
    def total(self) -> int:
        return sum(self.calls.values())

    def __torch_function__(self, func, types, args=(), kwargs=None):  # type: ignore[override]
        kwargs = kwargs or {}
        name = getattr(func, "__name__", str(func))
        reason = self._why_it_waits(name, args, kwargs)
        if reason is not None:
            self.calls[reason] += 1
        out = func(*args, **kwargs)
        if isinstance(out, torch.Tensor) and self._host_born(name, kwargs):
            self._host[id(out)] = weakref.ref(out)
        return out

    def _why_it_waits(self, name: str, args: tuple, kwargs: dict) -> str | None:
        """What the call would wait for on a GPU, or None."""
        first = args[0] if args else None
        on_host = isinstance(first, torch.Tensor) and self._is_host_born(first)
        if name in READS:
            return None if on_host else name
        if name in DATA_DEPENDENT:
            return None if (name == "repeat_interleave" and "output_size" in kwargs) else name
        if name == "__getitem__":
            return "boolean index" if _has_bool_index(args[1:]) else None
        if (name in ("to", "cuda", "copy_") and on_host) or (name in FROM_HOST and kwargs.get("device") is not None):
            return f"host -> device ({name})"
        return None

    def _is_host_born(self, tensor: torch.Tensor) -> bool:
        ref = self._host.get(id(tensor))
        return ref is not None and ref() is tensor

    def _host_born(self, name: str, kwargs: dict) -> bool:
        generator = kwargs.get("generator")
        host_draw = generator is not None and generator is not self.device_generator
        return name in FROM_HOST or (name in RANDOM and host_draw)


def _has_bool_index(index: tuple) -> bool:
    items = index[0] if index and isinstance(index[0], tuple) else index
    return any(isinstance(i, torch.Tensor) and i.dtype == torch.bool for i in items)
