"""The batch engine from Python: many independent runs (parameters, effects, input, span,
initial state), each reduced to metrics inside the Rust loop, optionally with its sensor
reading every few steps and its final state. ``idm_rs.sweep`` and the diagnosis's fits are
built on it; use it directly for a list of runs that is not a grid::

    from idm_rs.core.batch import Point, Structure, run
    pts = [Point(idm_rs.Params(m2=m2), waveform=idm_rs.Triangle()) for m2 in (0.2, 0.3)]
    out = run(pts, Structure("lps"), t_end=10e-3, dt=1e-8)
    out["final_position"]                    # x1(t_end) per point [m]

Points go to Rust as tables (one row per point); the waveform of every point of a batch is of
one family (triangle, sawtooth or sampled) with per-point fields.
"""

from __future__ import annotations

import functools
import math
import os
from dataclasses import dataclass, field
from typing import Any, Literal, Mapping, Optional, Sequence, Union, overload

import numpy as np
from numpy.typing import NDArray

from . import engine
from .declarations import StructureName
from .effects import Effects
from .params import Params
from .solver import Solver, resolve_solver
from .waveforms import STARTUP_CYCLES, Sampled, Waveform


@dataclass(frozen=True)
class Rig:
    """A friction test rig instead of the IDM: one body (mass ``m1``, normal force
    ``normal_force`` — set it: the default is the IDM's weight) on the same Leuven friction
    element, driven by the input u(t). ``drive="position"``: u [m] moves the far end of a
    spring ``stiffness`` [N/m] with a damper ``damping`` [N s/m] (a spring–slider);
    ``drive="force"``: u [N] is the force on the body; ``drive="closed_loop"``: u [m] is the
    reference of a servo whose force is ``gain * clip(kv * (kp * (u - x) - v), ±limit)`` [N]
    (``kp`` [1/s], ``kv`` [V s/m], ``gain`` [N/V], ``limit`` [V]; the EMPS benchmark's drive).
    Give it as ``model=Rig(...)``."""

    drive: Literal["position", "force", "closed_loop"] = "position"
    stiffness: float = 0.0
    damping: float = 0.0
    kp: float = 0.0
    kv: float = 0.0
    gain: float = 0.0
    limit: float = math.inf


@dataclass(frozen=True)
class Structure:
    """The model's structure: ``model`` "lps" (two lumped masses), "dps" (the PE as
    ``n_elements`` FEM bar elements) or "rig" (see :class:`Rig`), and whether the piezo
    hysteresis state h runs."""

    model: StructureName = "dps"
    n_elements: int = 4
    piezo_hysteresis: bool = True
    rig: Optional[Rig] = None

    @classmethod
    def of(cls, model: Union[str, Rig], n_elements: int = 4, piezo_hysteresis: bool = True) -> "Structure":
        """From ``simulate``'s keywords: ``model`` is "lps", "dps" or a :class:`Rig`."""
        if isinstance(model, Rig):
            return cls("rig", 1, bool(piezo_hysteresis), model)
        # ignore: any name; engine.RunConfig refuses one other than "lps" or "dps" with a ValueError
        return cls(str(model), int(n_elements), bool(piezo_hysteresis))  # type: ignore[arg-type]

    def config(self, **how: Any) -> Any:
        """An ``engine.RunConfig`` of this structure with the method settings ``how``."""
        rig = self.rig or Rig()
        return engine.RunConfig(model=self.model, n_elements=int(self.n_elements),
                                piezo_hysteresis=bool(self.piezo_hysteresis), rig_drive=rig.drive,
                                rig_stiffness=float(rig.stiffness), rig_damping=float(rig.damping),
                                rig_kp=float(rig.kp), rig_kv=float(rig.kv), rig_gain=float(rig.gain),
                                rig_limit=float(rig.limit), **how)


ParamValues = Union[Params, Mapping[str, Optional[float]]]


@dataclass(frozen=True, eq=False)
class Point:
    """One run of a batch. ``params``: a :class:`Params`, or a mapping of parameter values
    (missing names take Table 1; ``normal_force`` None = derived from the masses).
    ``t_end`` [s] overrides the batch's; ``t_start`` [s] and ``initial_state`` (see
    :class:`idm_rs.State`) restart a run mid-record."""

    params: ParamValues
    effects: Effects = field(default_factory=Effects)
    waveform: Optional[Waveform] = None
    t_end: Optional[float] = None
    t_start: float = 0.0
    initial_state: Optional[NDArray[np.float64]] = None


def param_row(params: ParamValues) -> list[float]:
    """A point's parameter row in the engine's order; NaN normal force = derived."""
    given: Mapping[str, Optional[float]]
    if isinstance(params, Params):
        given = params.to_dict(resolved=False)
    else:
        given = dict(params)
    defaults = _table1()
    row = []
    for name in engine.param_names():
        v = given.get(name, defaults.get(name))
        row.append(math.nan if v is None else float(v))
    return row


@functools.lru_cache(maxsize=1)
def _table1() -> dict[str, float]:
    """Table 1 (normal force absent: derived), built once: rows of many points reuse it."""
    return Params().to_dict(resolved=False)


@dataclass(frozen=True, eq=False)
class Tables:
    """Per-point tables, one row per point, as the engine takes them."""

    params: NDArray[np.float64]  #: (P, len(param_names())), NaN normal_force = derived
    effects: NDArray[np.float64]  #: (P, len(effect_names()))
    wave_kind: str  #: "triangle", "sawtooth" or "sampled"
    wave_fields: NDArray[np.float64]  #: (P, len(wave_fields(wave_kind)))
    sampled: Optional[tuple[NDArray[np.float64], NDArray[np.float64]]] = None
    t_ends: Optional[NDArray[np.float64]] = None
    t_starts: Optional[NDArray[np.float64]] = None
    initial_states: Optional[NDArray[np.float64]] = None

    @property
    def size(self) -> int:
        return int(self.params.shape[0])

    @classmethod
    def from_points(cls, points: Sequence[Point], waveform: Optional[Waveform] = None) -> "Tables":
        """Tables of `points` (each with its own waveform, or `waveform` for all); every waveform
        must be of one family."""
        given = [p.waveform or waveform for p in points]
        if any(w is None for w in given):
            raise ValueError("every point needs a waveform (or give one for all)")
        waves = [w for w in given if w is not None]  # all of them
        kinds = {w.batch_kind for w in waves}
        if len(kinds) != 1:
            raise ValueError(f"the points of one batch need one waveform family, got {sorted(kinds)}")
        kind = kinds.pop()
        names = engine.wave_fields(kind)
        sampled = None
        if kind == "sampled":
            first = waves[0]
            assert isinstance(first, Sampled)
            if any(not (isinstance(w, Sampled)  # always: one kind
                        and np.array_equal(w.t, first.t) and np.array_equal(w.voltage, first.voltage)) for w in waves):
                raise ValueError("the points of one batch share one sampled waveform")
            sampled = (first.t, first.voltage)
        fields = np.array([[w.batch_fields()[n] for n in names] for w in waves], dtype=np.float64)
        enames = engine.effect_names()
        effects = np.array([[getattr(p.effects, n) for n in enames] for p in points], dtype=float)
        params = np.array([param_row(p.params) for p in points], dtype=float)
        t_ends = None
        if any(p.t_end is not None for p in points):
            t_ends = np.array([math.nan if p.t_end is None else p.t_end for p in points], dtype=float)
        t_starts = np.array([p.t_start for p in points], dtype=float) if any(p.t_start for p in points) else None
        states = None
        if any(p.initial_state is not None for p in points):
            if any(p.initial_state is None for p in points):
                raise ValueError("give an initial state for every point of a batch, or for none")
            states = np.stack([np.asarray(p.initial_state, dtype=float) for p in points])
        return cls(params.reshape(len(points), -1), effects.reshape(len(points), -1), kind,
                   fields.reshape(len(points), -1), sampled, t_ends, t_starts, states)


def start(tables: Tables, structure: Structure, *, t_end: float, method: str = "rk4", dt: float = 1e-8,
          rtol: float = 1e-7, atol: float = 1e-7, first_step: Optional[float] = None, retries: int = 2,
          threads: Optional[int] = None, record_every: int = 0, final_states: bool = False,
          skip_cycles: int = STARTUP_CYCLES, sensitivities: Optional[Sequence[str]] = None,
          derivatives_only: bool = False, solver: Optional[Solver] = None) -> Any:
    """Start the batch on a background thread; returns an ``engine.BatchRun`` (``progress()``,
    ``wait(timeout)``, ``cancel()``, ``result()``). Settings as in :func:`run`; ``solver`` (an
    :class:`idm_rs.Solver`) gives the method's settings as one object."""
    how = resolve_solver(solver, dict(method=method, dt=dt, rtol=rtol, atol=atol, first_step=first_step,
                                      retries=retries),
                         dict(method="rk4", dt=1e-8, rtol=1e-7, atol=1e-7, first_step=None, retries=2), "batch")
    method, dt, rtol, atol, first_step, retries = (how["method"], how["dt"], how["rtol"], how["atol"],
                                                   how["first_step"], how["retries"])
    config = structure.config(method=method, dt=float(dt), rtol=float(rtol), atol=float(atol),
                              first_step=None if first_step is None else float(first_step), retries=int(retries),
                              threads=int(threads or os.cpu_count() or 1), record_every=int(record_every),
                              final_states=bool(final_states), skip_cycles=int(skip_cycles))
    t_ends = tables.t_ends
    if t_ends is not None:
        t_ends = np.where(np.isnan(t_ends), float(t_end), t_ends)
    return engine.start_batch(config, float(t_end), _c(tables.params), _c(tables.effects), tables.wave_kind,
                              _c(tables.wave_fields), tables.sampled, _c(t_ends), _c(tables.t_starts),
                              _c(tables.initial_states), sensitivity_names(sensitivities) or None,
                              bool(derivatives_only))


def run(points: Union[Sequence[Point], Tables], structure: Structure, *, t_end: float, **how: Any) -> dict[str, Any]:
    """Run a batch to the end and return its outputs: metric arrays (``final_position`` [m],
    ``step_per_cycle`` [m], ``peak_velocity`` [m/s], ``peak_friction`` [N], ``slip_fraction``,
    the steady-state metrics of sawtooth trains ``mean_velocity`` [m/s], ``step_mean``,
    ``step_std``, ``backslip`` [m], ``backslip_ratio``, ``direction``, then ``status``,
    ``diverged_at`` [s], ``dt_used`` [s], ``steps``), ``traces`` (sensor readings
    [m] every ``record_every`` RK4 steps from the start, one array per point) and
    ``final_states`` when asked: (points x state), NaN rows where a point did not finish, or a
    list of arrays when points differ in their state layout (different effect states).

    ``how``: ``method`` ("rk4", "dopri5" or "rodas4"), ``dt`` [s] (RK4 step), ``rtol``/``atol``
    and ``first_step`` [s] (adaptive), ``retries`` (RK4 retries at dt/2, dt/4 of a diverging
    point), ``threads``, ``record_every``, ``final_states``, ``skip_cycles`` (start-up cycles
    left out of the steady-state metrics, default :data:`~idm_rs.core.waveforms.STARTUP_CYCLES` = 2),
    ``sensitivities`` (names, as for :func:`idm_rs.simulate`; needs ``record_every``): then
    ``sensitivities`` is an array (points x names x samples) of d trace / d name (NaN where a
    point did not finish or its derivatives could not be taken, with the reason in ``reasons``), and
    ``sensitivity_names``; ``derivatives_only`` (with ``sensitivities``, RK4): the caller has
    every point's readings from a run of the same points that finished at ``dt``, so only the
    derivative passes run (their numbers bit for bit those after the run) and no ``traces``
    come back; ``solver`` (an :class:`idm_rs.Solver`) for the method's settings as one object."""
    tables = points if isinstance(points, Tables) else Tables.from_points(points)
    handle = start(tables, structure, t_end=t_end, **how)
    try:
        while not handle.wait(0.1):
            pass
    except KeyboardInterrupt:
        handle.cancel()
        raise
    out = dict(handle.result())
    if "final_states" in out:
        out["final_states"] = _stack_states(out["final_states"])
    if "sensitivities" in out:
        out["sensitivities"] = _stack_sensitivities(out["sensitivities"], len(out["sensitivity_names"]))
    return out


def sensitivity_names(names: Optional[Sequence[str]]) -> list[str]:
    """The names to differentiate with respect to, as a list (one string is one name)."""
    if names is None:
        return []
    if isinstance(names, str):
        return [names]
    out = list(names)
    bad = [n for n in out if not isinstance(n, str)]
    if bad:
        raise TypeError(f"sensitivities must be names (strings), got {bad[0]!r}")
    return out


def _stack_sensitivities(per_point: list[NDArray[np.float64]], n: int) -> NDArray[np.float64]:
    """(points x names x samples), NaN where a point has none (it did not finish); points of
    different record lengths are padded with NaN at the end."""
    samples = max((a.shape[1] for a in per_point), default=0)
    out = np.full((len(per_point), n, samples), np.nan)
    for i, a in enumerate(per_point):
        out[i, :, :a.shape[1]] = a
    return out


def _stack_states(states: list[NDArray[np.float64]]) -> Union[NDArray[np.float64], list[NDArray[np.float64]]]:
    """(points x state) with NaN rows for points that did not finish, when every finished point
    has one layout; otherwise the list (points with different effect states differ in size)."""
    sizes = {s.size for s in states if s.size}
    if len(sizes) != 1:
        return states if sizes else np.full((len(states), 0), np.nan)
    dim = sizes.pop()
    return np.stack([s if s.size else np.full(dim, np.nan) for s in states])


@overload
def _c(a: NDArray[np.float64]) -> NDArray[np.float64]: ...


@overload
def _c(a: Optional[NDArray[np.float64]]) -> Optional[NDArray[np.float64]]: ...


def _c(a: Optional[NDArray[np.float64]]) -> Optional[NDArray[np.float64]]:
    """C-contiguous float64 (the engine then reads it in place)."""
    return None if a is None else np.ascontiguousarray(a, dtype=np.float64)
