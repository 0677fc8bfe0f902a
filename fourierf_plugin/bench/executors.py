"""Where runs execute: a local process pool (default) or a Ray cluster, behind one ``map`` interface.

Why one interface: a sweep is many independent runs; the coordinator hands them to ``map`` and writes each result
as it arrives, so the results files are the same whichever executor ran them. Results come back in completion
order (a long run does not hold back the rows of the short ones); every result names its run.
"""

from __future__ import annotations

import multiprocessing
import os
import socket
import time
from collections.abc import Callable, Iterable, Iterator
from concurrent.futures import ProcessPoolExecutor, as_completed
from typing import Protocol, TypeVar

from fourierf_plugin.utils.errors import fail

T = TypeVar("T")
R = TypeVar("R")


class Executor(Protocol):
    def map(self, fn: Callable[[T], R], items: Iterable[T]) -> Iterator[R]:
        """Apply ``fn`` to every item, yielding results as they complete."""
        ...


def available_cores() -> int:
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:  # not Linux
        return os.cpu_count() or 1


def threads_per_worker(workers: int, threads: int | None, cores: int | None = None) -> int:
    """Torch threads for each run so that workers × threads never exceeds the cores."""
    cores = cores or available_cores()
    if workers < 1:
        fail(f"--workers {workers} is not valid", "pass --workers 1 or more")
    if workers > cores:
        fail(f"--workers {workers} exceeds the {cores} CPU cores here", f"pass --workers {cores} or fewer")
    if threads is None:
        return max(1, cores // workers)
    if threads < 1 or workers * threads > cores:
        fail(
            f"--workers {workers} × --threads {threads} does not fit the {cores} CPU cores here",
            f"pass --threads {max(1, cores // workers)} or fewer (or leave it out)",
        )
    return threads


class LocalExecutor:
    """A pool of ``workers`` processes (spawned, so no forked torch/OpenMP state).

    One worker runs the items in order in this process: nothing to gain from a pool, and errors keep their traceback.
    """

    def __init__(self, workers: int = 1) -> None:
        if workers < 1:
            fail(f"--workers {workers} is not valid", "pass --workers 1 or more")
        self.workers = workers

    def map(self, fn: Callable[[T], R], items: Iterable[T]) -> Iterator[R]:
        items = list(items)
        if self.workers == 1:
            yield from map(fn, items)
            return
        if not items:
            return
        context = multiprocessing.get_context("spawn")
        with ProcessPoolExecutor(max_workers=min(self.workers, len(items)), mp_context=context) as pool:
            futures = [pool.submit(fn, item) for item in items]
            for future in as_completed(futures):
                yield future.result()


def probe(nap_seconds: float = 0.0) -> tuple[str, int]:
    """(host, pid) of the process that ran it, after a nap: a trivial task to check an executor reaches its workers."""
    time.sleep(nap_seconds)
    return socket.gethostname(), os.getpid()


def import_ray():
    """The ray module, or a UserError saying how to install it."""
    try:
        import ray
    except ImportError:
        fail(
            "--executor ray needs the 'ray' package, which is not installed",
            "pip install 'fourierf[ray]' (or pip install ray), then start or join a cluster",
        )
    return ray


class RayExecutor:
    """Submit the same function as a Ray task per item; ``address`` None starts a local Ray instance.

    Each task reserves ``cpus_per_run`` CPUs (the run's torch threads) and ``gpus_per_run`` GPUs, so Ray packs as
    many runs per node as fit. Paths in the items (scene, output folder) must be visible to every node (a shared
    filesystem). ``init_kwargs`` go to ``ray.init`` (e.g. ``num_cpus`` of a local instance).
    """

    def __init__(
        self, address: str | None = None, cpus_per_run: float = 1, gpus_per_run: float = 0, **init_kwargs
    ) -> None:
        self.ray = import_ray()
        self.cpus_per_run = cpus_per_run
        self.gpus_per_run = gpus_per_run
        if not self.ray.is_initialized():
            try:
                self.ray.init(address=address, **init_kwargs)
            except (ConnectionError, ValueError, RuntimeError) as err:
                fail(
                    f"cannot connect to the Ray cluster at --ray-address {address}: {err}",
                    "start one with `ray start --head`, pass its address (or 'auto'), or leave --ray-address out "
                    "for a local instance",
                )

    def map(self, fn: Callable[[T], R], items: Iterable[T]) -> Iterator[R]:
        remote = self.ray.remote(num_cpus=self.cpus_per_run, num_gpus=self.gpus_per_run)(fn)
        pending = [remote.remote(item) for item in items]
        while pending:
            ready, pending = self.ray.wait(pending, num_returns=1)
            yield self.ray.get(ready[0])

    def shutdown(self) -> None:
        self.ray.shutdown()
