"""A sweep written into a Zarr store slab by slab, so that a grid larger than memory runs in
bounded memory: the store is laid out from the axes alone (1-D coordinates, the index space cut
into chunks of at most ``block_size`` points), each slab is one chunk run in memory and written
as it finishes, the run time is estimated from the first slab, and Ctrl-C keeps every slab
written (the rest status 0, "not run")."""

from __future__ import annotations

import dataclasses
import time
import warnings
from pathlib import Path
from typing import TYPE_CHECKING, Any, Callable, Iterator

import numpy as np

from ..core.interrupted import interrupted

if TYPE_CHECKING:
    import xarray

#: the reasons' type in a store: variable-length text (numpy >= 2), else fixed width
TEXT: Any = np.dtypes.StringDType() if hasattr(np.dtypes, "StringDType") else np.dtype("<U240")

#: a sweep whose first slab says it will take longer than this [s] is told so (a warning)
LONG_SWEEP_S = 3600.0


def chunk_shape(shape: tuple[int, ...], target: int) -> tuple[int, ...]:
    """The chunk of a grid of ``shape`` holding at most ``target`` points (at least one): the
    trailing axes whole while they fit, then a run along the next axis, 1 on the leading ones.
    A chunk is then one contiguous range of flat (C-order) point indices."""
    chunks = [1] * len(shape)
    inner = 1
    for axis in range(len(shape) - 1, -1, -1):
        if inner * shape[axis] <= target:
            chunks[axis] = shape[axis]
            inner *= shape[axis]
        else:
            chunks[axis] = max(1, target // inner)
            break
    return tuple(chunks)


def slabs(shape: tuple[int, ...], chunks: tuple[int, ...]) -> Iterator[tuple[slice, ...]]:
    """The chunks of the grid in C order, each as one slice per axis; generated, never listed
    (a 10^10-point grid has 10^5 and more)."""
    counts = [-(-n // c) for n, c in zip(shape, chunks)]
    for index in np.ndindex(*counts):
        yield tuple(slice(i * c, min(n, (i + 1) * c)) for i, c, n in zip(index, chunks, shape))


def _human(seconds: float) -> str:
    for unit, size in (("years", 365.25 * 86400), ("days", 86400), ("hours", 3600), ("minutes", 60)):
        if seconds >= 2 * size:
            return f"{seconds / size:.1f} {unit}"
    return f"{seconds:.0f} s"


def run_to_store(plan: Any, run: Any, path: Path, bar: Any,
                 run_slab: Callable[[Any, Any, Any], tuple["xarray.Dataset", bool]]) -> "xarray.Dataset":
    """Run ``plan`` slab by slab into the Zarr store at ``path`` (``run_slab(plan, run, bar)``
    runs a sub-grid in memory: (its Dataset, whether it finished)); returns the store opened
    lazily (no Dask graph, whatever the number of chunks). Ctrl-C raises KeyboardInterrupt whose
    ``partial`` is the store with the slabs written."""
    import xarray as xr
    import zarr

    shape = plan.shape
    chunks = chunk_shape(shape, run.block_size)
    t0 = time.perf_counter()
    complete, finished, laid_out = True, 0, False
    pending = None  # a slab run and not yet written

    def write(slab: "xarray.Dataset", region: tuple[slice, ...]) -> None:
        nonlocal laid_out
        if not laid_out:
            _layout(plan, slab, chunks).to_zarr(path, compute=False, mode="w-", consolidated=False)
            laid_out = True
        slab.drop_vars(list(slab.coords)).drop_attrs().to_zarr(
            path, region=dict(zip(plan.names, region)), mode="r+", consolidated=False)

    try:
        for region in slabs(shape, chunks):
            sub = dataclasses.replace(plan, values=tuple(v[r] for v, r in zip(plan.values, region)))
            slab, done = run_slab(sub, run, bar)
            slab["reason"] = slab["reason"].astype(TEXT)
            pending = (slab, region)
            write(slab, region)
            finished, pending = finished + int(slab.attrs["points_finished"]), None
            if finished == int(slab.attrs["points_finished"]):  # the first slab
                _say_how_long(plan.size, slab, time.perf_counter() - t0, bar)
            if not done:
                complete = False
                break
    except KeyboardInterrupt:  # between two slabs, or while one was written
        complete = False
        if pending is not None:  # a finished slab is kept whole
            write(*pending)
            finished += int(pending[0].attrs["points_finished"])
    if not laid_out:  # stopped before anything was run
        raise interrupted("sweep interrupted before its first slab finished: nothing was written", partial=None)
    group = zarr.open_group(str(path), mode="r+")
    group.attrs.update({"complete": int(complete), "points_finished": finished,
                        "wall_time_s": time.perf_counter() - t0})
    store: "xarray.Dataset" = xr.open_zarr(path, consolidated=False, chunks=None)
    if not complete:
        raise interrupted(f"sweep interrupted: {finished} of {plan.size} points written to {str(path)!r}; the rest "
                          "have status 0 (attrs['complete'] = 0; the store is the exception's .partial)",
                          partial=store)
    return store


def _layout(plan: Any, slab: "xarray.Dataset", chunks: tuple[int, ...]) -> "xarray.Dataset":
    """The whole grid's Dataset as one lazy (never computed) array per variable, with the Zarr
    chunks in its encoding, the 1-D coordinates of the axes and the attributes: what
    ``to_zarr(compute=False)`` needs to lay out the store. One Dask chunk per variable, so the
    layout costs the same for 10^2 and 10^10 points."""
    import dask.array as da
    import xarray as xr

    shape = plan.shape
    data_vars = {}
    for name, var in slab.data_vars.items():
        fill = "" if var.dtype == TEXT else (0 if var.dtype.kind in "ui" else np.nan)
        lazy = da.full(shape, fill, dtype=var.dtype, chunks=shape)  # type: ignore[no-untyped-call, unused-ignore]
        data_vars[name] = (var.dims, lazy, var.attrs)
    coords = {name: (name, vals, slab[name].attrs) for name, vals in zip(plan.names, plan.values)}
    ds = xr.Dataset(data_vars, coords=coords, attrs=dict(slab.attrs))
    for name in ds.data_vars:
        ds[name].encoding["chunks"] = chunks
    ds.attrs.update({"points": plan.size, "complete": 0, "points_finished": 0})
    return ds


def _say_how_long(points: int, slab: "xarray.Dataset", seconds: float, bar: Any) -> None:
    """After the first slab: the whole sweep's time at its rate, on the progress bar and, for a
    sweep of more than an hour, as a warning (a grid of months is said before it runs on)."""
    done = max(int(slab.attrs["points_finished"]), 1)
    total = points * seconds / done
    text = f"about {_human(total)} at the first slab's rate ({done / max(seconds, 1e-9):,.0f} points/s)"
    if bar is not None:
        bar.set_postfix_str(text, refresh=True)
    if total > LONG_SWEEP_S:
        warnings.warn(f"this sweep of {points:,} points takes {text}; Ctrl-C stops it and keeps the slabs written",
                      RuntimeWarning, stacklevel=4)
