"""The GPU kernel as a sweep backend (:class:`KernelBackend`, ``backend="cuda"`` or
``"kernel-cpu"``): what it admits (the gate, read from ``engine.kernel_accepts()``), each block's
columns packed without a loop per point, blocks streamed (the host packs the next while the
device runs one), failed points rerun on the CPU engine."""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Union

import numpy as np
from numpy.typing import NDArray

from ..core import engine, methods
from ..core.batch import param_row
from ..core.batch import start as start_batch
from ..core.effects import Effects
from ..core.params import Params
from .plan import METRICS, WAVE_FIELDS, SweepPlan

#: what a derived axis sets (the gate refuses a derived axis as it refuses the parameter)
DERIVED_SETS = {"mass_ratio": "m2", "pe_mass_ratio": "pe_density", "stiffness": "pe_youngs"}


@dataclass(frozen=True)
class KernelKind:
    """The GPU kernel as a backend kind (`name` "cuda" or "kernel-cpu"): the metrics and
    methods the kernel declares (``engine.kernel_accepts()``), the plans its gate admits, one
    device on this machine (no cluster)."""

    name: str

    def metrics(self) -> list[str]:
        return kernel_metrics()

    def check(self, method: str, client: Any) -> None:
        on_kernel = engine.kernel_accepts()["methods"]
        if method not in on_kernel:
            raise ValueError(f"backend={self.name!r} runs the methods {', '.join(map(repr, on_kernel))}; "
                             f"{method} runs on backend='cpu'")
        if client is not None:
            raise ValueError(f"backend={self.name!r} runs on this machine's device; drop 'client'")

    def admit(self, plan: SweepPlan, span: tuple[float, float]) -> None:
        check_kernel_admits(plan, self.name)
        if plan.own_t_end:
            shortest, longest = span
            raise ValueError(f"backend={self.name!r} runs every point to one t_end, and this grid's waveforms end "
                             f"between {shortest:g} and {longest:g} s: give t_end={longest:g} (the shorter ones "
                             "then rest until it) or use backend='cpu', which runs each point to its own end")

    def executor(self, threads: int, client: Any) -> str:
        return f"{self.name} kernel"

    def backend(self, threads: int, block_size: int, client: Any) -> "KernelBackend":
        return KernelBackend(self.name, threads, block_size)


def kernel_metrics() -> list[str]:
    """The metrics the kernel backends return (``engine.kernel_accepts()``), in METRICS order."""
    return [m for m in METRICS if m in engine.kernel_accepts()["metrics"]]


def check_kernel_admits(plan: SweepPlan, backend: str) -> None:
    """Refuse by default: a kernel backend runs a sweep only when the structure, the waveform
    family and its fields, and every Table 1 parameter and effect that is swept or differs from
    its default are among what the kernel implements (``engine.kernel_accepts()``, declared in
    rust/src/gpu/kernel.rs beside the packing); anything else is refused by name."""
    acc = engine.kernel_accepts()
    fix = "(use backend='cpu')"
    # nodes of a mechanism with elements: one per element boundary; without: its two bodies (the
    # engine refuses, by name, any model with more nodes than the kernel holds)
    with_elements = {d["name"]: bool(d["elements"]) for d in engine.structure_declarations()}
    nodes = plan.n_elements + 1 if with_elements.get(plan.model) else 2
    if plan.model not in acc["structures"] or nodes > acc["max_dof"]:
        raise ValueError(f"backend={backend!r} runs the IDM mechanisms ({', '.join(acc['structures'])}) with up to "
                         f"{acc['max_dof']} nodes ({acc['max_dof'] - 1} elements); got model={plan.model!r}, "
                         f"n_elements={plan.n_elements} {fix}")
    kind = plan.waveform.batch_kind
    if kind not in acc["waves"]:
        raise ValueError(f"backend={backend!r} runs {' and '.join(k.capitalize() for k in acc['waves'])} inputs, "
                         f"not a {type(plan.waveform).__name__} waveform {fix}")
    missing = [f for f in engine.wave_fields(kind) if f not in acc["waves"][kind]]
    if missing:
        raise ValueError(f"backend={backend!r} does not evaluate the {kind} field(s) {missing} {fix}")
    swept = set(plan.names) | {DERIVED_SETS[n] for n in plan.names if n in DERIVED_SETS}
    given, default = param_row(plan.params), param_row(Params())
    for name, v, d in zip(engine.param_names(), given, default):
        differs = not (v == d or (math.isnan(v) and math.isnan(d)))
        if name not in acc["params"] and (name in swept or differs):
            raise ValueError(f"backend={backend!r} does not implement parameter '{name}' "
                             f"({'swept' if name in swept else 'set'}) {fix}")
    no_effect = Effects()
    for name in engine.effect_names():
        if name not in acc["effects"] and (name in swept or getattr(plan.effects, name) != getattr(no_effect, name)):
            raise ValueError(f"backend={backend!r} does not implement effect parameter '{name}' "
                             f"({'swept' if name in swept else 'on'}) {fix}")


def kernel_block(plan: SweepPlan, start: int, stop: int) -> tuple[NDArray[np.float64], NDArray[np.float64],
                                                                 NDArray[np.intp], dict[str, Any], NDArray[np.bool_]]:
    """Flat points [start, stop) for the kernel, with no loop per point: the parameter and effect
    rows of the distinct points of the parameter axes (the engine's tables), each point's row, the
    wave's batch fields (a swept field per point, the others once), and the points whose wave
    is invalid only in combination (a sawtooth edge not shorter than its period)."""
    shape = plan.shape
    idx = np.unravel_index(np.arange(start, stop), shape)
    wave_axes = [a for a, n in enumerate(plan.names) if n in WAVE_FIELDS or n == "voltage"]
    param_axes = [a for a in range(len(shape)) if a not in wave_axes]
    if param_axes:
        sub = tuple(shape[a] for a in param_axes)
        key = np.ravel_multi_index([idx[a] for a in param_axes], sub)
        uniq, rows = np.unique(key, return_inverse=True)
        full = [np.zeros(uniq.size, dtype=np.intp)] * len(shape)
        for a, i in zip(param_axes, np.unravel_index(uniq, sub)):
            full[a] = i
        reps = np.ravel_multi_index(full, shape)
    else:
        reps, rows = np.zeros(1, dtype=np.intp), np.zeros(stop - start, dtype=np.intp)
    tables = plan.tables_at(reps)
    fields: dict[str, Any] = dict(plan.waveform.batch_fields())
    for a in wave_axes:
        name = "amplitude" if plan.names[a] == "voltage" else plan.names[a]
        fields[name] = plan.values[a][idx[a]]
    invalid = np.zeros(stop - start, dtype=bool)
    if plan.waveform.batch_kind == "sawtooth":
        period = 1.0 / np.asarray(fields["frequency"], dtype=float)
        invalid = np.broadcast_to(np.asarray(fields["rise"]) >= period, invalid.shape).copy()
        if invalid.any():  # such a point is not run: give it a valid edge, its result is discarded
            fields["rise"] = np.where(invalid, 0.5 * period, fields["rise"])
    return tables.params, tables.effects, rows, fields, invalid


@dataclass(frozen=True)
class KernelBackend:
    """The kernel on the GPU (`name` "cuda") or built for the CPU ("kernel-cpu"), `block_size`
    points per launch; `threads` for the CPU engine's reruns."""

    name: str
    threads: int
    block_size: int

    def run(self, plan: SweepPlan, out: dict[str, NDArray[Any]], bar: Any) -> bool:
        """The GPU kernel (or its CPU build) block by block, streamed: while the GPU runs a block
        the host packs the next and stores the last. RK4: diverged points are retried on the CPU
        engine at dt/2, dt/4 (``plan.retries``). Adaptive: the kernel runs Dormand-Prince at the
        plan's tolerances; a point that diverged or whose step collapsed there is rerun on the CPU
        engine with the plan's own method (``"auto"`` changes a stiff point to Rodas4 there) when
        ``plan.retries`` > 0. Ctrl-C keeps the finished blocks."""
        # through the package, where a test can stand in for a launch
        from ..gpu import launch_cuda, pack, run_cpu, wave_columns
        from ..gpu.backend import Finished, Launched

        threads, block_size, backend = self.threads, self.block_size, self.name
        adaptive = methods.is_adaptive(plan.method)
        config = plan.structure.config(method="rk4", dt=plan.dt)  # the constants do not depend on the method
        kind = plan.waveform.batch_kind
        n = plan.size
        pending = None
        try:
            for start in range(0, n, block_size):
                stop = min(n, start + block_size)
                params, effects, rows, fields, invalid = kernel_block(plan, start, stop)
                how: dict[str, Any] = (dict(method="dopri5", rtol=plan.rtol, atol=plan.atol, first_step=plan.first_step)
                                       if adaptive else {})
                batch = pack(config, params, effects, rows, wave_columns(kind, fields), plan.t_end, plan.dt, **how)
                handle: Union[Launched, Finished] = (launch_cuda(batch) if backend == "cuda"
                                                     else Finished(run_cpu(batch)))
                previous, pending = pending, (handle, start, stop, invalid)
                if previous is not None:
                    finish_block(plan, out, *previous, threads, bar)
            previous, pending = pending, None
            if previous is not None:
                finish_block(plan, out, *previous, threads, bar)
        except KeyboardInterrupt:
            if pending is not None and pending[0].done():  # a block the device had finished is kept
                try:
                    finish_block(plan, out, *pending, threads, bar)
                except KeyboardInterrupt:
                    pass
            return False
        return True


def finish_block(plan: SweepPlan, out: dict[str, NDArray[Any]], handle: Any, start: int, stop: int,
                 invalid: NDArray[np.bool_], threads: int, bar: Any) -> None:
    """Wait for a block, write its outputs straight into the sweep's columns, rerun its failed
    points on the CPU engine."""
    res = handle.result()
    adaptive = methods.is_adaptive(plan.method)
    sl = slice(start, stop)
    for k in ("final_position", "peak_velocity", "peak_friction", "slip_fraction", "status", "diverged_at"):
        out[k][sl] = res[k]
    ok = res["status"] == 1
    out["reason"][sl] = ""
    failed = np.flatnonzero(~ok) + start  # reasons are set point by point only where one is due
    if adaptive:
        out["dt_used"][sl] = np.where(ok, res["dt_used"], np.nan)
        out["steps"][sl] = np.where(ok, res["steps"], 0)
        crawled = res["crawled"][failed - start]
        out["reason"][failed[crawled]] = ("the step collapsed on the kernel (Dormand-Prince held at its stability "
                                          "limit; method='rodas4' or 'auto' on backend='cpu' runs it)")
        out["reason"][failed[~crawled]] = "diverged on the kernel"
    else:
        out["dt_used"][sl] = np.where(ok, plan.dt, np.nan)
        out["steps"][sl] = np.where(ok, int(round(plan.t_end / plan.dt)), 0)
        out["reason"][failed] = "diverged on the GPU kernel"
    cycles = getattr(plan.waveform, "cycles", None)
    if cycles is not None and "cycles" not in plan.names:
        out["step_per_cycle"][sl] = res["final_position"] / cycles
    if invalid.any():
        bad = np.flatnonzero(invalid) + start
        for k in ("final_position", "peak_velocity", "peak_friction", "slip_fraction", "step_per_cycle",
                  "diverged_at", "dt_used"):
            out[k][bad] = np.nan
        out["status"][bad] = 4
        out["steps"][bad] = 0
        out["reason"][bad] = "invalid: the sawtooth's rise is not shorter than its period"
        ok = ok & ~invalid
    bad = np.flatnonzero(~ok & ~invalid) + start
    if bad.size and plan.retries > 0:
        handle = start_batch(plan.tables_at(bad), plan.structure, t_end=plan.t_end, method=plan.method,
                             dt=plan.dt, rtol=plan.rtol, atol=plan.atol, first_step=plan.first_step,
                             retries=plan.retries, threads=threads, skip_cycles=plan.skip_cycles)
        handle.wait(1e9)
        again = handle.result()
        for k in out:
            out[k][bad] = again["reasons"] if k == "reason" else again[k]
        if adaptive:  # rerun on the CPU: say so where it finished
            fine = again["status"] == 1
            out["reason"][bad[fine]] = "failed on the kernel; finished on the CPU engine"
    if bar is not None:
        bar.update(stop - start)
