"""What a sweep is, whatever runs it: the plan of a grid (picklable, so that a Dask worker can
run any block of it), the engine's tables of any of its points, the columns every backend fills,
and a block run on the CPU engine to completion (a Dask task's unit of work)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Mapping

import numpy as np
from numpy.typing import NDArray

from ..core import engine, methods
from ..core.batch import Structure, Tables, param_row
from ..core.batch import start as start_batch
from ..core.declarations import Model
from ..core.effects import Effects
from ..core.params import Params
from ..core.waveforms import STARTUP_CYCLES, Sampled, Sawtooth, Triangle, Waveform

#: metric name -> (units, long name), declared once in the engine (``batch/metrics.rs``); the
#: steady state of a sawtooth train is over the cycles after `skip_cycles` (NaN for other inputs)
METRICS: dict[str, tuple[str, str]] = {name: (unit, long) for name, unit, long in engine.metric_columns()}

#: the steady-state metrics of a sawtooth train (the CPU backend computes them; NaN for other inputs)
STEADY_METRICS: tuple[str, ...] = ("mean_velocity", "step_mean", "step_std", "backslip", "backslip_ratio",
                                   "direction")

#: derived axes: name -> (units, long name)
DERIVED_AXES: dict[str, tuple[str, str]] = {
    "mass_ratio": ("1", "weight-to-main-body mass ratio m2/m1 (m1 fixed)"),
    "pe_mass_ratio": ("1", "PE-to-main-body mass ratio mPE/m1 (through pe_density)"),
    "stiffness": ("N/m", "PE stiffness kp = Ep Ap / l (through pe_youngs)"),
    "voltage": ("V", "drive amplitude"),
}

WAVE_FIELDS: dict[str, tuple[str, str]] = {
    "amplitude": ("V", "drive amplitude"),
    "rise": ("s", "rise (edge) time"),
    "fall": ("s", "fall time (triangle)"),
    "frequency": ("Hz", "drive frequency (sawtooth)"),
    "cycles": ("1", "number of drive cycles (sawtooth)"),
    "delay": ("s", "delay before the wave"),
}

STATUS_MEANINGS = "not_run ok ok_at_smaller_dt diverged invalid"

@dataclass(frozen=True)
class SweepPlan:
    """Everything needed to run any block of the grid (picklable for Dask)."""

    params: Params
    waveform: Waveform
    effects: Effects
    names: tuple[str, ...]
    values: tuple[NDArray[np.float64], ...]
    t_end: float
    dt: float
    model: Model
    n_elements: int
    piezo_hysteresis: bool
    method: str
    rtol: float
    atol: float
    retries: int
    first_step: float
    skip_cycles: int = STARTUP_CYCLES
    #: each point runs to its own waveform's end (``t_end`` is then the longest of them)
    own_t_end: bool = False

    @property
    def shape(self) -> tuple[int, ...]:
        return tuple(len(v) for v in self.values)

    @property
    def size(self) -> int:
        return int(np.prod(self.shape, dtype=np.int64))

    @property
    def structure(self) -> Structure:
        return Structure(self.model, self.n_elements, self.piezo_hysteresis)

    def tables(self, start: int, stop: int) -> Tables:
        """The engine's tables of flat points [start, stop)."""
        return self.tables_at(np.arange(start, stop))

    def tables_at(self, flat: NDArray[np.int64]) -> Tables:
        """The engine's tables of the flat points `flat`."""
        n = flat.size
        idx = np.unravel_index(flat, self.shape)
        pnames = engine.param_names()
        pm = np.tile(param_row(self.params), (n, 1))  # NaN normal_force: derived per point
        enames = engine.effect_names()
        em = np.tile([getattr(self.effects, e) for e in enames], (n, 1)).astype(float)
        wnames = engine.wave_fields(self.waveform.batch_kind)
        base = self.waveform.batch_fields()
        wm = np.tile([base[c] for c in wnames], (n, 1)).astype(float)
        for axis, (name, vals) in enumerate(zip(self.names, self.values)):
            v = vals[idx[axis]]
            if name in pnames:
                pm[:, pnames.index(name)] = v
            elif name in enames:
                em[:, enames.index(name)] = v
            elif name in ("voltage", "amplitude"):
                wm[:, wnames.index("amplitude")] = v
            elif name in WAVE_FIELDS:
                wm[:, wnames.index(name)] = v
        # derived axes, applied after the plain ones so they see the swept m1, Ap, l
        col = {name: j for j, name in enumerate(pnames)}
        for axis, (name, vals) in enumerate(zip(self.names, self.values)):
            v = vals[idx[axis]]
            if name == "mass_ratio":
                pm[:, col["m2"]] = v * pm[:, col["m1"]]
            elif name == "pe_mass_ratio":
                pm[:, col["pe_density"]] = v * pm[:, col["m1"]] / (pm[:, col["pe_area"]] * pm[:, col["pe_length"]])
            elif name == "stiffness":
                pm[:, col["pe_youngs"]] = v * pm[:, col["pe_length"]] / pm[:, col["pe_area"]]
        sampled = (self.waveform.t, self.waveform.voltage) if isinstance(self.waveform, Sampled) else None
        t_ends = None
        if self.own_t_end:
            t_ends = durations(self.waveform, {c: wm[:, j] for j, c in enumerate(wnames)})
            if not methods.is_adaptive(self.method):
                t_ends = snap_to_steps(t_ends, self.dt)
        return Tables(pm, em, self.waveform.batch_kind, wm, sampled, t_ends)


def snap_to_steps(t: Any, dt: float) -> Any:
    """``t`` [s] (a number or an array) rounded to a whole number of steps ``dt`` where it is
    within 1e-9 (relative, or absolute below 1 s) of one; elsewhere unchanged."""
    t = np.asarray(t, dtype=float)
    k = np.round(t / dt)
    out = np.where(np.abs(k * dt - t) <= 1e-9 * np.maximum(1.0, np.abs(t)), k * dt, t)
    return float(out) if out.ndim == 0 else out


def durations(waveform: Waveform, fields: Mapping[str, Any]) -> NDArray[np.float64]:
    """The end of each point's waveform [s] from its batch fields (arrays or scalars)."""
    if isinstance(waveform, Sawtooth):
        d = (np.asarray(fields["delay"], float)
             + np.asarray(fields["cycles"], float) / np.asarray(fields["frequency"], float))
    elif isinstance(waveform, Triangle):
        d = np.asarray(fields["delay"], float) + np.asarray(fields["rise"], float) + np.asarray(fields["fall"], float)
    else:
        d = np.asarray(waveform.duration, float)
    return np.atleast_1d(d).astype(float)


def start_block(plan: SweepPlan, start: int, stop: int, threads: int) -> Any:
    """Flat points [start, stop) of a plan started on the CPU engine (a running batch)."""
    return start_batch(plan.tables(start, stop), plan.structure, t_end=plan.t_end, method=plan.method, dt=plan.dt,
                       rtol=plan.rtol, atol=plan.atol, first_step=plan.first_step, retries=plan.retries,
                       threads=threads, skip_cycles=plan.skip_cycles)


def run_block(plan: SweepPlan, start: int, stop: int, threads: int = 1) -> dict[str, NDArray[Any]]:
    """Run flat points [start, stop) of a plan to completion; the unit of work of a Dask task.
    ``threads`` caps the rayon threads so that Dask workers do not oversubscribe their cores."""
    run = start_block(plan, start, stop, threads)
    run.wait(1e9)
    return dict(run.result())


#: the columns every backend fills, by dtype: the metrics and the bookkeeping
OUTPUTS: dict[str, Any] = {
    **{m: np.float64 for m in METRICS},
    "status": np.uint8,
    "diverged_at": np.float64,
    "dt_used": np.float64,
    "steps": np.uint64,
}


def store(out: dict[str, NDArray[Any]], res: Mapping[str, Any], start: int, stop: int) -> None:
    """A finished block's results into the sweep's columns `out` at flat points [start, stop)."""
    for k in out:
        out[k][start:stop] = res["reasons"] if k == "reason" else res[k]
