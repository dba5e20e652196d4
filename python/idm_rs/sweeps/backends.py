"""How a sweep's blocks are run, behind two protocols: a backend's kind (:class:`BackendKind`:
what it computes and admits, refused by name before anything runs, and the executor it makes)
and the executor (:class:`SweepBackend`: fill the plan's columns block by block, and say whether
every block finished; Ctrl-C keeps what finished). Here the CPU engine (:class:`CpuEngine`) and
its two executors, rayon threads on this machine (:class:`LocalEngine`) and a Dask cluster
(:class:`DaskCluster`); the GPU kernel's kind and executor (CUDA, or the same source built for
the CPU) are in :mod:`.kernel_sweep`. :func:`backend_kind` picks a kind by name; ``sweep.py``
asks only these protocols."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Protocol

from numpy.typing import NDArray

from .plan import METRICS, SweepPlan, run_block, start_block, store

#: the backends' names (``sweep(backend=...)``)
BACKENDS: tuple[str, ...] = ("cpu", "cuda", "kernel-cpu")

#: smallest number of points per Dask task (the scheduler's overhead is ~1 ms per task)
DASK_MIN_BLOCK = 10_000




class SweepBackend(Protocol):
    """What runs a sweep's blocks (made by a :class:`BackendKind`)."""

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


class BackendKind(Protocol):
    """A backend as ``sweep`` sees it before and while it runs: what it computes, what it
    refuses (each check raises a ValueError naming the fix), the words of its executor for the
    Dataset's attributes, and the executor itself."""

    @property
    def name(self) -> str:
        """The name ``sweep(backend=...)`` takes."""
        ...

    def metrics(self) -> list[str]:
        """The metrics it computes, in METRICS order."""
        ...

    def check(self, method: str, client: Any) -> None:
        """Refuse a method it does not run or a cluster it does not use."""
        ...

    def admit(self, plan: SweepPlan, span: tuple[float, float]) -> None:
        """Refuse a plan it cannot run (`span`: the shortest and the longest waveform end [s])."""
        ...

    def executor(self, threads: int, client: Any) -> str:
        """How it runs, in words (the Dataset's ``executor`` attribute)."""
        ...

    def backend(self, threads: int, block_size: int, client: Any) -> SweepBackend:
        """The executor of its blocks."""
        ...


@dataclass(frozen=True)
class CpuEngine:
    """The CPU engine: every metric, every method, every plan; rayon threads here or, given a
    Dask `client`, a cluster."""

    name: str = "cpu"

    def metrics(self) -> list[str]:
        return list(METRICS)

    def check(self, method: str, client: Any) -> None:
        return None

    def admit(self, plan: SweepPlan, span: tuple[float, float]) -> None:
        return None

    def executor(self, threads: int, client: Any) -> str:
        return "dask" if client is not None else f"local rayon, {threads} threads"

    def backend(self, threads: int, block_size: int, client: Any) -> SweepBackend:
        return DaskCluster(client, block_size) if client is not None else LocalEngine(threads, block_size)


def backend_kind(name: str) -> BackendKind:
    """The backend called `name` ("cpu": the engine; "cuda", "kernel-cpu": the GPU kernel on the
    device or built for the CPU); any other name refused with the choices."""
    if name == "cpu":
        return CpuEngine()
    if name in BACKENDS:
        from .kernel_sweep import KernelKind

        return KernelKind(name)
    raise ValueError(f"parameter 'backend' must be {', '.join(map(repr, BACKENDS[:-1]))} or {BACKENDS[-1]!r}, "
                     f"got {name!r}")
