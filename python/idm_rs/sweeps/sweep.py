"""Parameter sweeps: the outer product of a grid of values, each point reduced to metrics inside
the Rust batch engine (no trajectories stored), returned as a labelled ``xarray.Dataset``.

Points are sent to Rust in blocks, so memory is O(points x metrics) plus one block. Locally the
blocks run on a rayon pool with the GIL released while a tqdm bar follows progress; Ctrl-C stops
within about a second and returns what finished. With ``client=`` (a ``dask.distributed.Client``)
each block is a Dask task on the cluster instead.
"""

from __future__ import annotations

import math
import os
import time
from dataclasses import dataclass, fields
from pathlib import Path
from typing import TYPE_CHECKING, Any, Literal, Mapping, Optional, Sequence, Union

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ..core import engine, methods, options
from ..core.declarations import EFFECT_PARAMS, GRAVITY, Model, elements_of, structure
from ..core.effects import Effects
from ..core.interrupted import interrupted
from ..core.methods import MethodName
from ..core.params import PARAM_INFO, Params
from ..core.solver import Solver, resolve_solver
from ..core.waveforms import STARTUP_CYCLES, Sampled, Sawtooth, Triangle, Waveform
from .backends import BackendKind, backend_kind
from .plan import DERIVED_AXES, METRICS, OUTPUTS, STATUS_MEANINGS, STEADY_METRICS, WAVE_FIELDS, SweepPlan, durations

if TYPE_CHECKING:
    import xarray

def _train_span(waveform: Waveform, names: Sequence[str], values: Sequence[NDArray[np.float64]]
                ) -> tuple[float, float, dict[str, float]]:
    """(shortest, longest) waveform end over the grid [s], and the swept wave fields of a point
    whose waveform is the longest. A waveform's end is a sum of terms each growing or shrinking
    with one field, so the extremes sit at the axes' ends: O(axes), whatever the grid's size."""
    base = dict(waveform.batch_fields())
    lo, hi = dict(base), dict(base)
    where: dict[str, float] = {}
    for name, v in zip(names, values):
        field = "amplitude" if name == "voltage" else name
        if field not in WAVE_FIELDS or field == "amplitude":
            continue
        longer = float(v.min()) if field == "frequency" else float(v.max())
        shorter = float(v.max()) if field == "frequency" else float(v.min())
        hi[field], lo[field] = longer, shorter
        where[name] = longer
    return float(durations(waveform, lo)[0]), float(durations(waveform, hi)[0]), where


def _axis_info(name: str) -> tuple[str, str]:
    if name in PARAM_INFO:
        sym, units, meaning = PARAM_INFO[name]
        return units, f"{meaning} ({sym})"
    if name in DERIVED_AXES:
        return DERIVED_AXES[name]
    if name in WAVE_FIELDS:
        return WAVE_FIELDS[name]
    unit = next(d.unit for d in EFFECT_PARAMS if d.name == name)
    return unit, f"effect parameter {name}"


def _check_grid(grid: Mapping[str, ArrayLike],
                waveform: Waveform) -> tuple[tuple[str, ...], tuple[NDArray[np.float64], ...]]:
    if not grid:
        raise ValueError("grid is empty: give at least one axis, e.g. {'mass_ratio': np.linspace(0.25, 2, 8)}")
    known = set(PARAM_INFO) | set(DERIVED_AXES) | set(WAVE_FIELDS) | {f.name for f in fields(Effects)}
    names, values = [], []
    for name, vals in grid.items():
        if name not in known:
            raise ValueError(f"unknown sweep axis '{name}'; known: {sorted(known)}")
        v = np.asarray(vals, dtype=float)
        if v.ndim > 1:
            raise ValueError(f"sweep axis '{name}' must be 1-D, got an array of shape {v.shape}; "
                             "give each dimension as its own axis")
        v = v.ravel()
        if v.size == 0:
            raise ValueError(f"sweep axis '{name}' is empty")
        if not np.all(np.isfinite(v)):
            raise ValueError(f"sweep axis '{name}' has non-finite values")
        if name in WAVE_FIELDS or name == "voltage":
            kind = {Triangle: ("amplitude", "rise", "fall", "delay"),
                    Sawtooth: ("amplitude", "rise", "frequency", "cycles", "delay"),
                    Sampled: ("amplitude",)}[type(waveform)]
            if (name if name != "voltage" else "amplitude") not in kind:
                raise ValueError(f"sweep axis '{name}' does not apply to a {type(waveform).__name__} waveform")
        names.append(name)
        values.append(v)
    if "mass_ratio" in names and "m2" in names:
        raise ValueError("sweep axes 'mass_ratio' and 'm2' both set m2; keep one")
    if "stiffness" in names and "pe_youngs" in names:
        raise ValueError("sweep axes 'stiffness' and 'pe_youngs' both set pe_youngs; keep one")
    if "pe_mass_ratio" in names and "pe_density" in names:
        raise ValueError("sweep axes 'pe_mass_ratio' and 'pe_density' both set pe_density; keep one")
    if "voltage" in names and "amplitude" in names:
        raise ValueError("sweep axes 'voltage' and 'amplitude' are the same; keep one")
    return tuple(names), tuple(values)


def sweep(
    params: Params,
    waveform: Waveform,
    grid: Mapping[str, ArrayLike],
    *,
    t_end: Optional[float] = None,
    dt: Optional[float] = None,
    model: Model = "dps",
    n_elements: Optional[int] = None,
    metrics: Optional[Sequence[str]] = None,
    method: MethodName = "rk4",
    rtol: Optional[float] = None,
    atol: Optional[float] = None,
    first_step: Optional[float] = None,
    skip_cycles: int = STARTUP_CYCLES,
    retries: int = 2,
    piezo_hysteresis: bool = True,
    effects: Optional[Effects] = None,
    progress: Union[bool, str] = True,
    client: Any = None,
    threads: Optional[int] = None,
    block_size: int = 65_536,
    backend: Literal["cpu", "cuda", "kernel-cpu"] = "cpu",
    out: Optional[Union[str, "os.PathLike[str]"]] = None,
    solver: Optional[Solver] = None,
) -> "xarray.Dataset":
    """Sweep the outer product of ``grid`` and return the metrics as an ``xarray.Dataset``.

    ``grid`` maps axis names to 1-D arrays, one dimension per name in the given order. A name is
    any :class:`Params` field, any waveform field (``amplitude``, ``frequency``, ``rise``,
    ``fall``, ``cycles``, ``delay``), any :class:`Effects` field, or a derived axis:
    ``mass_ratio`` (m2/m1, m1 fixed), ``pe_mass_ratio`` (mPE/m1 through ``pe_density``),
    ``stiffness`` (kp [N/m] through ``pe_youngs``), ``voltage`` (the amplitude [V]).
    The normal force is recomputed per point as (m1+m2+mPE)·g unless ``params.normal_force`` is
    set or swept.

    ``t_end`` [s]: by default (None) each point runs to the end of its own waveform (a 50 Hz
    train of 6 cycles for 0.12 s, a 100 Hz one for 0.06 s; a triangle to the end of its fall; a
    sampled input to its last sample), so no train is cut short. Given, every point runs to it
    (past a waveform's end the voltage is 0 V, or the last sample); a ``t_end`` that ends before
    some point's sawtooth train is refused with the point and the ``t_end`` it needs (the steady
    state and the step per cycle of a cut train would be silently wrong).

    ``method="rk4"``: fixed step ``dt`` [s] (default 1e-8), the reference; each point equals
    ``simulate()`` bit for bit. A point that diverges is retried at dt/2, dt/4 (``retries``
    times) and then flagged (``status`` 3 with ``diverged_at``), never returned as a silent NaN.
    ``method="dopri5"`` (explicit Dormand-Prince 5(4)) or ``"rodas4"`` (linearly implicit
    Rosenbrock 4(3) with the analytic Jacobian; several times fewer steps where friction is
    stiff): adaptive with ``rtol``/``atol`` (default 1e-7; ``atol`` in units of each state's
    natural scale: the free stroke d33·V for positions, Fs for friction) and no ``dt``; ``first_step`` [s] is an
    optional first trial step (default 1e-8; a ``dt`` given with an adaptive method is taken as
    its first step, as in earlier versions). ``method="auto"``: the fastest adaptive setting
    measured to keep every benchmark point within 1 nm of RK4 (:data:`idm_rs.core.methods.AUTO`,
    rtol = atol = 3e-7) when no tolerance is given; a given ``rtol``/``atol`` is honoured.

    Metrics (computed in the Rust loop): ``final_position`` [m], ``step_per_cycle`` [m] (sawtooth
    trains), ``peak_velocity`` [m/s], ``peak_friction`` [N], ``slip_fraction`` [-], and for
    sawtooth trains the steady state over the cycles after the first ``skip_cycles`` (default
    :data:`~idm_rs.core.waveforms.STARTUP_CYCLES`, 2, as in :func:`idm_rs.characterize`):
    ``mean_velocity`` [m/s], ``step_mean`` and ``step_std`` [m] per cycle, ``backslip`` [m] per
    cycle (travel against the net direction) and ``backslip_ratio`` (over the travel along it),
    ``direction`` (+1, -1, 0 stalled); always with ``status``, ``diverged_at``
    [s], ``dt_used`` [s], ``steps``. Sweep ``frequency`` x ``voltage`` for the velocity map,
    ``load_force`` for the load curve.

    ``backend="cuda"`` runs points one per GPU thread (CuPy; ``pip install 'idm-rs[cuda]'``)
    with what the kernel admits (``engine.kernel_accepts()``: every Table 1 parameter, every
    effect and library term (its right-hand side is generated from the engine's model),
    Triangle or Sawtooth input, LPS or DPS up to 5 elements; anything else swept or set, and a
    sweep that switches a lag on at some points and off at others, is refused by name): ``method="rk4"`` (points
    that diverge are retried on the CPU at dt/2, dt/4), ``"dopri5"`` or ``"auto"`` (Dormand-Prince
    at the method's tolerances, with the engine's step collapse check; a point that diverges or
    whose step collapses there is rerun on the CPU with the same method, where ``"auto"`` can
    change it to Rodas4; ``retries=0`` flags it instead). ``"kernel-cpu"`` runs that same kernel
    source compiled for the CPU (slow; it is how the tests verify the GPU physics without a
    GPU). The kernels do not compute the steady-state train metrics (:data:`STEADY_METRICS`):
    asked for by name on a kernel backend they are refused; by default (``metrics=None``: all)
    they are left out of the Dataset there (``attrs["metrics_not_computed"]`` names them).

    ``progress``: a tqdm bar of the points (a string: the bar's label), its estimate from the
    whole run's average rate.

    Ctrl-C stops within about a second and raises a ``KeyboardInterrupt`` whose ``partial``
    (:func:`idm_rs.partial_result`) is the Dataset of the finished points (others NaN,
    ``attrs["complete"] == 0``), or with ``out`` the store with the slabs written.

    Memory: the results take :data:`BYTES_PER_POINT` bytes per point; a grid whose results do
    not fit in the memory available is refused up front with what it needs. ``out`` (a path
    ending ``.zarr``; needs ``zarr``) writes the results into a Zarr store slab by slab along
    the first axis as they finish, so a sweep larger than memory runs, and returns the store
    opened lazily (``xarray.open_zarr``); an interrupted one keeps the slabs written.
    ``client`` (a ``dask.distributed.Client``) runs blocks of at least 10⁴ points as Dask tasks,
    each capped at the worker's thread count.

    Parameters
    ----------
    params : Params
        The device every point starts from; the grid's axes override its fields.
    waveform : Triangle, Sawtooth or Sampled
        The drive every point starts from ([V], [s]).
    grid : mapping of str to 1-D array
        Axis name -> values; the points are the outer product, in the given order.
    t_end : float, optional
        End of every run [s]; None: each point to its own waveform's end.
    dt, method, rtol, atol, first_step
        The integrator, as for :func:`idm_rs.simulate`.
    model : {"lps", "dps"}
        The structure; ``n_elements`` FEM elements for the DPS (default 4).
    metrics : sequence of str, optional
        The metrics kept (default all of :data:`METRICS`).
    skip_cycles : int
        Start-up cycles left out of the steady state (fewer than the train's cycles where a
        steady-state metric is computed).
    retries : int
        RK4 retries at dt/2, dt/4, ... of a point that diverges (>= 0).
    piezo_hysteresis : bool
        Bouc-Wen hysteresis of the PE force.
    effects : Effects, optional
        Extra physics of the catalogue.
    progress : bool or str
        A progress bar (a string: its label).
    client : dask.distributed.Client, optional
        Run blocks as Dask tasks.
    threads : int, optional
        Threads on this machine (default: every core).
    block_size : int
        Points per block (and, with ``out``, the most points of a slab in memory).
    backend : {"cpu", "cuda", "kernel-cpu"}
        Where the points run.
    out : path, optional
        A Zarr store (``….zarr``) to write the results into slab by slab.
    solver : Solver, optional
        ``method``, ``dt``, ``rtol``, ``atol``, ``first_step`` and ``retries`` as one object
        (:class:`idm_rs.Solver`); refused where a flat keyword says otherwise.

    Returns
    -------
    xarray.Dataset
        One variable per metric plus ``status``, ``diverged_at`` [s], ``dt_used`` [s],
        ``steps`` and ``reason`` over the grid's dimensions, with units in the attributes; with
        ``out`` the store opened lazily.

    Raises
    ------
    ValueError
        An unknown axis or metric, a bad option (named), a ``t_end`` that cuts a train short.
    MemoryError
        A grid whose results cannot fit in memory (with ``out`` the hint to write a store).
    KeyboardInterrupt
        Ctrl-C; its ``partial`` holds the finished points.

    Examples
    --------
    >>> import numpy as np, idm_rs
    >>> ds = idm_rs.sweep(idm_rs.Params(), idm_rs.Sawtooth(amplitude=80.0, frequency=200.0, cycles=6),
    ...                   {"voltage": np.linspace(40, 120, 5)}, model="lps", method="auto", progress=False)
    >>> ds["mean_velocity"].sizes["voltage"]
    5
    """
    if not isinstance(params, Params):
        raise TypeError(f"params must be idm_rs.Params, got {type(params).__name__}")
    how = resolve_solver(solver, dict(method=method, dt=dt, rtol=rtol, atol=atol, first_step=first_step,
                                      retries=retries),
                         dict(method="rk4", dt=None, rtol=None, atol=None, first_step=None, retries=2), "sweep")
    method, dt, rtol, atol, first_step, retries = (how["method"], how["dt"], how["rtol"], how["atol"],
                                                   how["first_step"], how["retries"])
    kind = backend_kind(backend)
    metrics, not_computed = _metrics_kept(metrics, kind)
    structure(model)  # an IDM structure, else a ValueError naming the choices
    asked = methods.check(method)
    options.tolerances_for(method, rtol, atol)
    method, rtol, atol = methods.resolve(method, rtol, atol)
    adaptive = method in methods.ADAPTIVE
    if adaptive and first_step is None and dt is not None:
        first_step = dt  # the adaptive methods' first step was once given as dt: still honoured
    if dt is None or adaptive:
        dt = 1e-8
    kind.check(method, client)
    names, values = _check_grid(grid, waveform)
    effects = effects or Effects()
    first = float(first_step) if first_step is not None else 1e-8
    # start-up cycles that skip a whole train leave its steady-state metrics NaN: refused where
    # they are computed (a sweep of final positions alone may run short trains)
    steady = any(m in STEADY_METRICS for m in metrics)
    skips = options.skip_cycles(skip_cycles, _fewest_cycles(waveform, names, values) if steady else None)
    retries = options.count("retries", retries, minimum=0)
    block_size = options.count("block_size", block_size)
    threads = options.threads(threads)
    n_elements = options.elements(model, n_elements)
    t_end, own, given, (shortest, longest) = _t_end_rule(t_end, waveform, names, values, method, dt)
    plan = SweepPlan(params, waveform, effects, names, values, float(t_end), float(dt), model, int(n_elements),
                     bool(piezo_hysteresis), method, float(rtol), float(atol), int(retries), first, skips, own)
    kind.admit(plan, (shortest, longest))
    if out is None:
        _check_memory(plan.size, out_hint=True)
    _validate_axes(plan)

    threads = int(threads or os.cpu_count() or 1)
    attrs = _attrs(plan, asked, given, (shortest, longest), threads, client, kind, not_computed)
    run = _Run(metrics, attrs, threads, block_size, client, kind)
    if out is not None:
        return _run_to_store(plan, run, Path(out), progress)
    bar = None
    try:
        bar = _progress_bar(plan.size, progress)
        ds, complete = _run_in_memory(plan, run, bar)
    finally:
        if bar is not None:
            bar.close()
    if not complete:
        raise interrupted(f"sweep interrupted: {ds.attrs['points_finished']} of {plan.size} points finished; the "
                          "rest are NaN (attrs['complete'] = 0; the Dataset is the exception's .partial)", partial=ds)
    return ds


def _metrics_kept(metrics: Optional[Sequence[str]], kind: BackendKind) -> tuple[list[str], list[str]]:
    """(the metrics kept, those the backend does not compute): unknown names and names the
    backend does not compute are refused by name."""
    admitted = kind.metrics()
    if metrics is None:
        not_computed = [m for m in METRICS if m not in admitted]
        return [m for m in METRICS if m not in not_computed], not_computed
    metrics = list(metrics)
    unknown = [m for m in metrics if m not in METRICS]
    if unknown:
        raise ValueError(f"unknown metric(s) {unknown}; known: {list(METRICS)}")
    refused = [m for m in metrics if m not in admitted]
    if refused:
        what = "steady-state " if all(m in STEADY_METRICS for m in refused) else ""
        raise ValueError(f"backend={kind.name!r} does not compute the {what}metric(s) {refused} (use backend='cpu')")
    return metrics, []


def _t_end_rule(t_end: Optional[float], waveform: Waveform, names: Sequence[str],
               values: Sequence[NDArray[np.float64]], method: str, dt: float
               ) -> tuple[float, bool, bool, tuple[float, float]]:
    """(the run's end [s], whether each point runs to its own waveform's end, whether t_end was
    given, (shortest, longest) waveform end [s]). A given t_end that cuts a sawtooth train short
    is refused, naming the point whose train is the longest."""
    shortest, longest, where = _train_span(waveform, names, values)
    given = t_end is not None
    if t_end is None:
        own = shortest != longest
        t_end = longest
    else:
        own = False
        if isinstance(t_end, bool) or not (float(t_end) > 0 and math.isfinite(float(t_end))):
            raise ValueError(f"parameter 't_end' must be a positive time [s], got {t_end!r}")
        slack = 1e-12 * longest if methods.is_adaptive(method) else 0.5 * float(dt)
        if isinstance(waveform, Sawtooth) and float(t_end) < longest - slack:
            at = " of the point " + ", ".join(f"{k} = {v:g}" for k, v in where.items()) if where else ""
            raise ValueError(f"t_end = {float(t_end):g} s ends before the sawtooth train{at} "
                             f"(it ends at {longest:g} s): "
                             "its cycles would be cut short and its steady state and step per cycle silently wrong. "
                             f"Give t_end >= {longest:g} s, or leave t_end out so that each point runs to the end "
                             "of its own train")
    return float(t_end), own, given, (shortest, longest)


def _attrs(plan: SweepPlan, asked: str, given: bool, span: tuple[float, float], threads: int, client: Any,
           kind: BackendKind, not_computed: list[str]) -> dict[str, Any]:
    """The Dataset's fixed attributes: how the sweep was run (`asked`: the method as the user
    named it; `span`: the shortest and longest waveform end [s])."""
    from ..core.engine import __version__

    params, effects, waveform, piezo_hysteresis = plan.params, plan.effects, plan.waveform, plan.piezo_hysteresis
    model, n_elements, method, dt, first, t_end = (plan.model, plan.n_elements, plan.method, plan.dt,
                                                   plan.first_step, plan.t_end)
    rtol, atol, retries, skips, own = plan.rtol, plan.atol, plan.retries, plan.skip_cycles, plan.own_t_end
    adaptive = methods.is_adaptive(method)
    shortest, longest = span
    attrs: dict[str, Any] = {
        "idm_rs_version": __version__,
        "model": model,
        "n_elements": elements_of(model, n_elements),
        "method": method,
        "method_asked": asked,
        "dt_s": float(dt) if not adaptive else math.nan,
        "first_step_s": first if adaptive else math.nan,
        "t_end_s": float(t_end),
        "t_end_rule": (f"each point to its own waveform's end ({shortest:g}-{longest:g} s)" if own
                       else "as given" if given else "the waveform's end"),
        "rtol": float(rtol) if adaptive else math.nan,
        "atol": float(atol) if adaptive else math.nan,
        "retries": int(retries),
        "skip_cycles": skips,
        "piezo_hysteresis": int(piezo_hysteresis),
        "waveform": repr(waveform),
        "normal_force_rule": "as set" if params.normal_force is not None else f"(m1+m2+mPE)*{GRAVITY:g} per point",
        "executor": kind.executor(threads, client),
        "backend": kind.name,
        "metrics_not_computed": ", ".join(not_computed),
    }
    for name, value in params.to_dict(resolved=False).items():
        attrs[f"param_{name}"] = value
    for name, value in effects.active().items():
        attrs[f"effect_{name}"] = value
    return attrs


def _fewest_cycles(waveform: Waveform, names: Sequence[str], values: Sequence[NDArray[np.float64]]) -> Optional[int]:
    """The fewest cycles of a sawtooth train over the grid (None for another input), for the
    start-up cycles' check."""
    if not isinstance(waveform, Sawtooth):
        return None
    if "cycles" in names:  # a value that is no count is an invalid point with its own reason
        v = np.asarray(values[list(names).index("cycles")], dtype=float)
        whole = v[(v >= 1) & (v == np.floor(v))]
        return int(whole.min()) if whole.size else None
    return int(waveform.cycles)


@dataclass(frozen=True)
class _Run:
    """How a plan is run and labelled: the metrics kept, the Dataset's fixed attributes, the
    executor."""

    metrics: Sequence[str]
    attrs: Mapping[str, Any]
    threads: int
    block_size: int
    client: Any
    kind: BackendKind


def _run_in_memory(plan: SweepPlan, run: _Run, bar: Any) -> tuple["xarray.Dataset", bool]:
    """Every point of ``plan`` into one Dataset in memory; (the Dataset, whether it finished)."""
    import xarray as xr

    n = plan.size
    out = {k: np.full(n, np.nan if t is np.float64 else 0, dtype=t) for k, t in OUTPUTS.items()}
    out["reason"] = np.full(n, "not run", dtype=object)
    t0 = time.perf_counter()
    complete = True
    try:
        complete = run.kind.backend(run.threads, run.block_size, run.client).run(plan, out, bar)
    except KeyboardInterrupt:  # between blocks or before the first: nothing finished is lost
        complete = False
    wall = time.perf_counter() - t0

    names, shape = plan.names, plan.shape
    coords = {}
    for name, vals in zip(names, plan.values):
        units, long_name = _axis_info(name)
        coords[name] = (name, vals, {"units": units, "long_name": long_name})
    data_vars: dict[str, tuple[Any, ...]] = {}
    for m in run.metrics:
        units, long_name = METRICS[m]
        data_vars[m] = (names, out[m].reshape(shape), {"units": units, "long_name": long_name})
    data_vars["status"] = (names, out["status"].reshape(shape), {
        "long_name": "point status", "flag_values": np.arange(5, dtype=np.uint8), "flag_meanings": STATUS_MEANINGS})
    data_vars["diverged_at"] = (names, out["diverged_at"].reshape(shape),
                                {"units": "s", "long_name": "time of divergence"})
    data_vars["dt_used"] = (names, out["dt_used"].reshape(shape), {
        "units": "s", "long_name": "step used (rk4) or smallest accepted step (adaptive)"})
    data_vars["steps"] = (names, out["steps"].reshape(shape), {"long_name": "integration steps taken"})
    data_vars["reason"] = (names, out["reason"].reshape(shape), {
        "long_name": "why the status is not ok (empty where it is)"})
    ds = xr.Dataset(data_vars, coords=coords)
    ds.attrs.update(run.attrs)
    ds.attrs.update({
        "complete": int(complete),
        "points": n,
        "points_finished": int(np.count_nonzero(out["status"])),
        "wall_time_s": wall,
    })
    return ds, complete


#: bytes of results per point in memory: every metric column and the bookkeeping columns, plus
#: the reason's reference (the strings themselves are shared: one "not run", one "")
BYTES_PER_POINT: int = sum(np.dtype(t).itemsize for t in OUTPUTS.values()) + np.dtype(object).itemsize

#: the share of the memory available now that a sweep's results may take
MEMORY_SHARE: float = 0.8


def _available_memory() -> Optional[int]:
    """Bytes of memory available now (Linux: MemAvailable; elsewhere the free pages), or None."""
    try:
        with open("/proc/meminfo") as f:
            for line in f:
                if line.startswith("MemAvailable:"):
                    return int(line.split()[1]) * 1024
    except OSError:
        pass
    try:
        return int(os.sysconf("SC_AVPHYS_PAGES") * os.sysconf("SC_PAGE_SIZE"))
    except (ValueError, OSError, AttributeError):
        return None


def _check_memory(points: int, out_hint: bool) -> None:
    """Refuse up front a grid whose results cannot fit in memory, saying what it needs."""
    need = points * BYTES_PER_POINT
    have = _available_memory()
    if have is None or need <= MEMORY_SHARE * have:
        return
    gib = 2.0**30
    raise MemoryError(f"this grid of {points:,} points needs {need / gib:.1f} GiB for its results ({BYTES_PER_POINT} "
                      f"bytes per point) and {have / gib:.1f} GiB of memory is available: sweep fewer points"
                      + (", or write the results to a Zarr store as the blocks finish (sweep(..., out='sweep.zarr'), "
                         "CLI --out sweep.zarr), which keeps one block in memory" if out_hint else ""))


def _run_to_store(plan: SweepPlan, run: _Run, path: Path, progress: Union[bool, str]) -> "xarray.Dataset":
    """The grid slab by slab into the Zarr store at ``path`` (:mod:`.sweep_store`); returns the
    store opened lazily. Ctrl-C keeps the slabs written (the rest ``status`` 0)."""
    from .store import chunk_shape, run_to_store

    if path.suffix.lower() != ".zarr":
        raise ValueError(f"parameter 'out' must name a Zarr store (…/name.zarr), got {str(path)!r}")
    if path.exists():
        raise ValueError(f"parameter 'out': {str(path)!r} exists; remove it or name another store")
    try:
        import zarr  # noqa: F401
    except ImportError:
        raise ImportError("sweep(..., out=...) writes a Zarr store: pip install 'idm-rs[store]' (zarr)") from None
    _check_memory(int(np.prod(chunk_shape(plan.shape, run.block_size))), out_hint=False)  # one slab in memory
    bar = None
    try:
        bar = _progress_bar(plan.size, progress)
        return run_to_store(plan, run, path, bar, _run_in_memory)
    finally:
        if bar is not None:
            bar.close()


def _validate_axes(plan: SweepPlan) -> None:
    """Fail fast, with the core's message, on a setting every point shares (step, duration,
    model) or an axis value that is invalid on its own: the points where one axis takes each of
    its values and the others their first are checked before any work. (A point invalid only
    in combination is flagged with status 4 instead.)"""
    cross = {0}
    for a, n in enumerate(plan.shape):
        for i in range(n):
            m = [0] * len(plan.shape)
            m[a] = i
            cross.add(int(np.ravel_multi_index(m, plan.shape)))
    flat = np.array(sorted(cross))
    tables = plan.tables_at(flat)
    pnames, enames = engine.param_names(), engine.effect_names()
    wnames = engine.wave_fields(tables.wave_kind)
    config = plan.structure.config(method=plan.method, dt=plan.dt, rtol=plan.rtol, atol=plan.atol,
                                   first_step=plan.first_step)
    for k in range(flat.size):
        p = {n: float(v) for n, v in zip(pnames, tables.params[k]) if not (n == "normal_force" and math.isnan(v))}
        eff = {n: float(v) for n, v in zip(enames, tables.effects[k]) if v != 0.0}
        bt, bv = plan.waveform.with_fields(dict(zip(wnames, tables.wave_fields[k]))).breakpoints()
        engine.check_run(p, eff, np.ascontiguousarray(bt, dtype=float), np.ascontiguousarray(bv, dtype=float),
                         0.0, plan.t_end, config)


def _progress_bar(total: int, show: Union[bool, str]) -> Any:
    """A points bar (``show`` a string: its label). Its estimate is the whole run's average rate
    (tqdm's smoothing 0): the points that finish first are the easy ones, and a rate smoothed
    over the last few blocks promised 28 s for a sweep of ten minutes."""
    if not show:
        return None
    from tqdm.auto import tqdm

    return tqdm(total=total, unit="pt", desc=show if isinstance(show, str) else "idm-rs sweep", smoothing=0.0)
