"""How a sweep's blocks are run: one protocol (:class:`SweepBackend`: fill the plan's columns
block by block, and say whether every block finished; Ctrl-C keeps what finished) and the CPU
engine's two executors, rayon threads on this machine (:class:`LocalEngine`) and a Dask cluster
(:class:`DaskCluster`). The GPU kernel's backend (CUDA, or the same source built for the CPU)
lives with the kernel, in ``gpu/kernel_sweep.py``; :func:`backend_for` picks one by name."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Protocol

from numpy.typing import NDArray

from .plan import SweepPlan, run_block, start_block, store

#: smallest number of points per Dask task (the scheduler's overhead is ~1 ms per task)
DASK_MIN_BLOCK = 10_000




class SweepBackend(Protocol):
    """What runs a sweep's blocks."""

    def run(self, plan: SweepPlan, out: dict[str, NDArray[Any]], bar: Any) -> bool:
        """Fill `out` (the plan's columns, flat) block by block, advancing the progress `bar`
        (or None); False where Ctrl-C stopped it (the finished blocks kept)."""
        ...


@dataclass(frozen=True)
class LocalEngine:
    """The CPU engine on this machine: `block_size` points at a time on `threads` rayon threads."""

    threads: int
    block_size: int

    def run(self, plan: SweepPlan, out: dict[str, NDArray[Any]], bar: Any) -> bool:
        threads, block_size = self.threads, self.block_size
        n = plan.size
        run = None
        start = stop = 0
        try:
            for start in range(0, n, block_size):
                stop = min(n, start + block_size)
                run = start_block(plan, start, stop, threads)
                seen = 0
                while not run.wait(0.1):
                    if bar is not None:
                        p = run.progress()
                        bar.update(p - seen)
                        seen = p
                res = run.result()
                run = None
                if bar is not None:
                    bar.update(stop - start - seen)
                store(out, res, start, stop)
        except KeyboardInterrupt:
            # Ctrl-C anywhere: stop the workers, keep every finished point
            if run is not None:
                run.cancel()
                try:
                    store(out, run.result(), start, stop)
                except RuntimeError:
                    pass  # the block's result was already taken
            return False
        return True


@dataclass(frozen=True)
class DaskCluster:
    """The CPU engine on a Dask cluster: one task per block of at least DASK_MIN_BLOCK points,
    each worker thread running its block with one rayon thread."""

    client: Any
    block_size: int

    def run(self, plan: SweepPlan, out: dict[str, NDArray[Any]], bar: Any) -> bool:
        client, block = self.client, max(self.block_size, DASK_MIN_BLOCK)
        from dask.distributed import as_completed

        n = plan.size
        # one task per block; each worker thread runs one block with one rayon thread
        futures = {}
        for start in range(0, n, block):
            stop = min(n, start + block)
            fut = client.submit(run_block, plan, start, stop, 1, pure=False)
            futures[fut] = (start, stop)
        try:
            for fut in as_completed(futures):  # type: ignore[no-untyped-call, unused-ignore]
                start, stop = futures[fut]
                store(out, fut.result(), start, stop)
                if bar is not None:
                    bar.update(stop - start)
        except KeyboardInterrupt:
            for fut in futures:
                fut.cancel()
            return False
        return True


def backend_for(name: str, threads: int, block_size: int, client: Any) -> SweepBackend:
    """The backend called `name` ("cpu": on `client`'s cluster when one is given; "cuda",
    "kernel-cpu": the GPU kernel)."""
    if name == "cpu":
        return DaskCluster(client, block_size) if client is not None else LocalEngine(threads, block_size)
    from .kernel_sweep import KernelBackend

    return KernelBackend(name, threads, block_size)
