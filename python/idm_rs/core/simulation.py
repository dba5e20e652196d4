"""One simulation: ``simulate()`` (its result: :mod:`.simulation_result`)."""

from __future__ import annotations

import dataclasses
import math
import warnings
from typing import TYPE_CHECKING, Any, Callable, Mapping, Optional, Sequence, Union

import numpy as np
from numpy.typing import ArrayLike

from . import engine, methods, options
from .declarations import Model, elements_of
from .effects import Effects
from .external_force import ExternalForce
from .interrupted import interrupted, partial_result
from .methods import MethodName
from .params import Params
from .simulation_result import EnergyBudget, SimulationResult
from .solver import Solver, resolve_solver
from .state import State
from .waveforms import Sampled, Sawtooth, Triangle, Waveform

#: above this many RK4 steps simulate() warns that the run will be long
LONG_RUN_STEPS = 1e8

if TYPE_CHECKING:

    from .batch import Rig

DivergenceError = engine.DivergenceError


#: pieces a long RK4 run is cut into for its progress bar
PROGRESS_PIECES = 100


def _in_pieces(common: dict[str, Any], t_start: Optional[float], t_end: float, dt: float, save_every: int,
               initial_state: Optional[ArrayLike]) -> SimulationResult:
    """An RK4 run in pieces of whole ``save_every`` blocks of steps, each continued from the last
    one's final state, under a progress bar of steps: the same saved times and, RK4 being
    continued bit for bit on its step grid, the same values as one run."""
    from tqdm.auto import tqdm

    if t_start is None:
        t_start = initial_state.t if isinstance(initial_state, State) else 0.0
    steps = int(round((t_end - t_start) / dt))
    per = max(save_every, (steps // PROGRESS_PIECES) // save_every * save_every)
    ends = [t_start + k * per * dt for k in range(1, -(-steps // per))] + [t_end]
    pieces: list[SimulationResult] = []
    state, start = initial_state, t_start
    with tqdm(total=steps, unit="step", unit_scale=True, desc="idm-rs simulate", smoothing=0.0) as bar:
        for end in ends:
            try:
                r = simulate(t_start=start, t_end=end, initial_state=state, **common)
            except KeyboardInterrupt as stop:
                # Ctrl-C can land in the Python around a piece's engine call too, where the stop
                # carries no trajectory: what finished is then the pieces before it (or nothing)
                last = partial_result(stop)
                done = pieces + ([last] if last is not None else [])
                kept = _joined(done) if done else None
                if kept is not None and end != ends[-1]:
                    # each piece may be whole (a Ctrl-C as one ended), the run is not
                    kept = dataclasses.replace(kept, complete=False)
                raise interrupted(str(stop), partial=kept) from None
            pieces.append(r)
            bar.update(int(round((end - start) / dt)))
            state, start = r.final_state, end
    return _joined(pieces)


def _joined(pieces: list[SimulationResult]) -> SimulationResult:
    """Consecutive pieces of one run as one result (each piece's first saved time is the last's
    final one, kept once)."""
    first, last = pieces[0], pieces[-1]
    n = first.t.size
    joined: dict[str, Any] = {}
    for f in dataclasses.fields(SimulationResult):
        v = getattr(first, f.name)
        if isinstance(v, np.ndarray) and v.ndim >= 1 and v.shape[0] == n and f.name not in (
                "sensitivities", "final_state_sensitivities"):
            joined[f.name] = np.concatenate([v] + [getattr(p, f.name)[1:] for p in pieces[1:]])
    return dataclasses.replace(last, **joined)


def _result_of(out: Mapping[str, Any], params: Params, waveform: Waveform, model: str, n_elements: int,
               step: float, piezo_hysteresis: bool, effects: Effects, energy: bool, method: str, rtol: float,
               atol: float) -> SimulationResult:
    """The engine's output of one run as a :class:`SimulationResult` (`rtol`, `atol` NaN for a
    fixed-step method)."""
    complete = bool(out["complete"])
    budget = _energy_budget(out) if energy else None
    return SimulationResult(
        t=out["t"],
        nodes=out["nodes"],
        velocities=out["velocities"],
        friction=out["friction"],
        fh=out["fh"],
        g=out["g"],
        h=out["h"],
        voltage=out["voltage"],
        piezo_force=out["piezo_force"],
        reading=out["reading"],
        final_position=float(out["final_state"][0]) if complete else float(out["nodes"][-1, 0]),
        params=params,
        waveform=waveform,
        model=model,
        n_elements=n_elements,
        dt=step,
        piezo_hysteresis=piezo_hysteresis,
        effects=effects,
        energy=budget,
        final_state=State(out["final_state"], out["state_components"] if complete else [], float(out["t"][-1])),
        method=method,
        rtol=rtol,
        atol=atol,
        complete=complete,
        sensitivity_names=tuple(out.get("sensitivity_names", ())),
        sensitivities=out.get("sensitivities", np.zeros((0, 0))),
        final_state_sensitivities=out.get("final_state_sensitivities", np.zeros((0, 0))),
    )


def _built_keeping_the_run(build: Callable[[], SimulationResult]) -> SimulationResult:
    """`build()`, but a Ctrl-C that lands after the engine returned — in the Python that turns its
    output into a result, where no engine watch sees it — keeps the run: the result is built
    again and rides on the KeyboardInterrupt as its ``partial``."""
    try:
        return build()
    except KeyboardInterrupt:
        result = build()
        raise interrupted(f"simulate interrupted after its run reached t = {result.t[-1]:g} s (the result is in "
                          "the exception's .partial)", partial=result) from None


def _check_types(params: object, waveform: object, external_force: object) -> None:
    """A TypeError naming the argument that is not of its idm_rs type."""
    if not isinstance(params, Params):
        raise TypeError(f"params must be idm_rs.Params, got {type(params).__name__}")
    if external_force is not None and not isinstance(external_force, ExternalForce):
        raise TypeError(f"external_force must be idm_rs.ExternalForce, got {type(external_force).__name__}")
    if not isinstance(waveform, (Triangle, Sawtooth, Sampled)):
        raise TypeError(f"waveform must be an idm_rs waveform (Triangle, Sawtooth or Sampled), got {waveform!r}")


def _start_time(t_start: Optional[float], initial_state: Optional[ArrayLike], waveform: Waveform) -> float:
    """The run's start [s]: as given, else the initial state's own time (a :class:`State`), else
    0. A start after 0 from rest with the drive already on warns (a voltage step)."""
    if t_start is None:
        return initial_state.t if isinstance(initial_state, State) else 0.0
    if initial_state is None and t_start > 0 and float(np.interp(t_start, *waveform.breakpoints())) != 0.0:
        v0 = float(np.interp(t_start, *waveform.breakpoints()))
        warnings.warn(f"t_start = {t_start:g} s without an initial_state: the run starts from rest with the drive "
                      f"already at {v0:.4g} V (a voltage step); pass initial_state=<a result's final_state> to "
                      "continue a run", UserWarning, stacklevel=3)
    return t_start


def _warn_if_long(t_start: float, t_end: float, step: float) -> None:
    """Say so when an RK4 run of [t_start, t_end] [s] at `step` [s] will take minutes."""
    n = (t_end - t_start) / step
    if n > LONG_RUN_STEPS:
        warnings.warn(f"{n:.2g} RK4 steps (t_end = {t_end:g} s at dt = {step:g} s) take minutes or more (or use "
                      "method='auto'); Ctrl-C stops the run and raises KeyboardInterrupt, whose .partial keeps the "
                      "trajectory so far", RuntimeWarning, stacklevel=3)


def _energy_budget(out: Mapping[str, Any]) -> EnergyBudget:
    """The energy and momentum budgets of an engine run's output (``energy=True``)."""
    acc = out["accounting"]
    return EnergyBudget(kinetic=out["kinetic"], strain=out["strain"], input_work=acc[:, 0], friction_work=acc[:, 1],
                        damping_work=acc[:, 2], external_work=acc[:, 3], momentum=out["momentum"],
                        friction_impulse=acc[:, 4], rayleigh_impulse=acc[:, 5], external_impulse=acc[:, 6])


def simulate(
    params: Params,
    waveform: Waveform,
    t_end: float,
    dt: Optional[float] = None,
    model: Union[Model, "Rig"] = "dps",
    n_elements: Optional[int] = None,
    save_every: int = 100,
    *,
    piezo_hysteresis: bool = True,
    effects: Optional[Effects] = None,
    energy: bool = False,
    method: MethodName = "rk4",
    rtol: Optional[float] = None,
    atol: Optional[float] = None,
    first_step: Optional[float] = None,
    t_start: Optional[float] = None,
    initial_state: Optional[ArrayLike] = None,
    sensitivities: Optional[Sequence[str]] = None,
    external_force: Optional[ExternalForce] = None,
    progress: bool = False,
    solver: Optional[Solver] = None,
) -> SimulationResult:
    """Simulate the IDM over [``t_start``, ``t_end``] s, from rest or from ``initial_state``.

    ``model`` is ``"lps"`` (two lumped masses), ``"dps"`` (the PE as ``n_elements`` FEM bar
    elements, default 4; another model warns that it ignores a count other than 1), or an
    :class:`idm_rs.core.batch.Rig` (a friction test rig: one body on the friction element, the
    waveform its drive position [m] or force [N]; use ``piezo_hysteresis=False``).

    ``method="rk4"`` (the reference): fixed step ``dt`` [s] (default 1e-8). The waveform's
    breakpoints must fall on step boundaries and ``dt`` must divide the span; otherwise a
    ValueError says which breakpoint and suggests a ``dt``. A step too large for the structure is
    refused up front (its damped modes: a fine bar's stiffness-proportional damping, not its
    undamped frequency, sets the limit; ``engine.rk4_step_limit``), with a step that fits the
    input; one too large for the friction state during sliding raises
    :class:`DivergenceError` with the time and a smaller step to try.
    ``method="dopri5"`` (explicit Dormand-Prince 5(4)) or ``"rodas4"`` (linearly implicit
    Rosenbrock 4(3), L-stable: far fewer steps where the friction state is stiff): adaptive, with
    ``rtol`` and ``atol`` (default 1e-7; ``atol`` in units of each state's natural scale: the
    free stroke d33·V for positions, Fs for forces) and no ``dt``; ``first_step`` [s] is an
    optional first trial step (as ``solve_ivp``'s); they land exactly on every breakpoint.
    ``method="auto"``: the adaptive setting measured to stay within 1 nm of RK4
    (:data:`idm_rs.core.methods.AUTO`, rtol = atol = 3e-7) when no tolerance is given; a given
    ``rtol``/``atol`` is honoured (the 1 nm measurement is for AUTO's). ``save_every`` counts
    accepted steps either way.

    ``initial_state`` (a :class:`State`, e.g. a previous result's ``final_state``, or any array
    of the model's state size) with ``t_start`` [s] continues or restarts a run (``t_start``
    defaults to the state's own time for a :class:`State`, else 0): with RK4 and a
    ``t_start`` on the step grid, ``simulate(..., t_end=4e-3)`` followed by
    ``simulate(..., t_start=4e-3, t_end=10e-3, initial_state=r.final_state)`` equals the 10 ms
    run bit for bit. ``energy=True`` integrates the energy and momentum budgets alongside
    (``result.energy``; they then start from the initial state's accounting components). The GIL
    is released while the Rust core runs.

    ``sensitivities``: names to differentiate the readings with respect to — any Table 1
    parameter (``"mu_k"``), any effect parameter (``"k_ground"``; a lag's time constant only
    while its effect is on) or a component of the initial state (``"q0"``, ``"v0"``, ``"fh"``;
    see :meth:`State.components`). ``result.sensitivity(name)`` is then d ``reading`` / d name at
    every saved time, the exact derivative of this discrete run (forward-mode dual numbers
    through the same right-hand side and integrator; an adaptive method's accepted steps are
    held), not a finite difference; ``result.final_state_sensitivities`` the same for the final
    state. With the normal force left to its default it follows the masses (d/d m1 includes
    it). At the friction law's kinks (v1 = 0, dg/dt = 0) the derivative is the one-sided one of
    the branch the run took. Cost: about 2-3 plain runs for one name, 6-9 for four to eight
    (docs/SENSITIVITIES.md).

    ``external_force``: an :class:`idm_rs.ExternalForce`, a sampled force [N] on the main body or
    the weight added to the model's forces (an unknown load, a disturbance, a force a test puts
    on the device); its samples are differentiable as ``"f_ext[k]"`` (``force.knot_names()``).

    Ctrl-C stops the run within about 50 ms and raises a ``KeyboardInterrupt`` whose ``partial``
    (:func:`idm_rs.partial_result`) is the result up to there (``complete`` False; a Ctrl-C as
    the run ends: the whole result, ``complete`` True).

    Parameters
    ----------
    params : Params
        The device (SI units; defaults: the paper's Table 1; docs/PARAMETERS.md lists every field).
    waveform : Triangle, Sawtooth or Sampled
        The PE voltage [V] against time [s].
    t_end : float
        End of the run [s].
    dt : float, optional
        RK4 step [s] (default 1e-8); for an adaptive method, taken as its first trial step.
    model : {"lps", "dps"} or Rig
        The lumped 2-DOF model, the FEM bar, or a friction test rig.
    n_elements : int, optional
        FEM elements of the DPS (default 4).
    save_every : int
        Keep every ``save_every``-th step (accepted step of an adaptive method).
    piezo_hysteresis : bool
        Bouc-Wen hysteresis of the PE force (the paper's model has it).
    effects : Effects, optional
        Extra physics of the catalogue (docs/PARAMETERS.md); none by default.
    energy : bool
        Integrate the energy and momentum budgets alongside (``result.energy``).
    method : {"rk4", "dopri5", "rodas4", "auto"}
        The integrator.
    rtol, atol : float, optional
        Tolerances of the adaptive methods (``atol`` in each state's natural scale).
    first_step : float, optional
        First trial step of an adaptive method [s].
    t_start : float, optional
        Start of the run [s] (default: the state's own time, or 0).
    initial_state : State or array, optional
        The state to start from (a previous result's ``final_state``).
    sensitivities : sequence of str, optional
        Names to differentiate the readings with respect to.
    external_force : ExternalForce, optional
        A sampled force [N] on the main body or the weight.
    progress : bool
        A progress bar over the steps, for a long RK4 run: the run is cut into about 100 pieces
        on its save grid, each continued from the last one's final state (bit for bit the same
        result). Ignored by the adaptive methods and with ``energy`` or ``sensitivities``.
    solver : Solver, optional
        ``method``, ``dt``, ``rtol``, ``atol`` and ``first_step`` as one object
        (:class:`idm_rs.Solver`); refused where a flat keyword says otherwise.

    Returns
    -------
    SimulationResult
        The saved trajectory, ``final_position`` x1(t_end) [m] and ``final_state``.

    Raises
    ------
    ValueError
        A setting out of its domain, a step that does not fit the input or is unstable for the
        structure; the message names the parameter and a value that works.
    DivergenceError
        The run left its bounds (the time and a step to try in the message).
    KeyboardInterrupt
        Ctrl-C; its ``partial`` holds the trajectory so far.

    Examples
    --------
    >>> import idm_rs
    >>> r = idm_rs.simulate(idm_rs.Params(), idm_rs.Triangle(amplitude=80.0, rise=0.5e-3, fall=9.5e-3),
    ...                     t_end=10e-3, model="lps", method="auto")
    >>> round(r.final_position * 1e6, 2)   # x1(10 ms) [µm]
    1.68
    """
    _check_types(params, waveform, external_force)
    how = resolve_solver(solver, dict(method=method, dt=dt, rtol=rtol, atol=atol, first_step=first_step),
                         dict(method="rk4", dt=None, rtol=None, atol=None, first_step=None), "simulate")
    method, dt, rtol, atol, first_step = how["method"], how["dt"], how["rtol"], how["atol"], how["first_step"]
    t_end = options.time("t_end", t_end)
    effects = effects or Effects()
    n_elements = options.elements(model, n_elements)
    save_every = options.count("save_every", save_every)
    options.tolerances_for(method, rtol, atol)
    method, rtol, atol = methods.resolve(method, rtol, atol)
    adaptive = methods.is_adaptive(method)
    if not adaptive and dt is None:
        dt = 1e-8
    step = float(first_step if adaptive and first_step is not None else (dt if dt is not None else 1e-8))
    if progress and not adaptive and not energy and not sensitivities:
        return _in_pieces(dict(params=params, waveform=waveform, dt=dt, model=model, n_elements=n_elements,
                               save_every=save_every, piezo_hysteresis=piezo_hysteresis, effects=effects,
                               method=method, external_force=external_force),
                          0.0 if t_start is None and initial_state is None else t_start, t_end, step, save_every,
                          initial_state)
    from .batch import Structure, sensitivity_names

    structure = Structure.of(model, int(n_elements), bool(piezo_hysteresis))
    config = structure.config(
        method=method, dt=step, rtol=float(rtol), atol=float(atol), first_step=step)
    t_start = _start_time(t_start, initial_state, waveform)
    names = sensitivity_names(sensitivities)
    bt, bv = waveform.breakpoints()
    y0 = None if initial_state is None else np.ascontiguousarray(initial_state, dtype=float).ravel()
    if not adaptive:
        _warn_if_long(t_start, t_end, step)
    out = engine.simulate(
        params._given(),
        effects.active(),
        np.ascontiguousarray(bt, dtype=float),
        np.ascontiguousarray(bv, dtype=float),
        float(t_start),
        float(t_end),
        config,
        int(save_every),
        bool(energy),
        y0,
        names or None,
        None if external_force is None else external_force.engine_arg(),
    )
    result = _built_keeping_the_run(lambda: _result_of(
        out, params, waveform, structure.model, elements_of(structure.model, n_elements), step,
        bool(piezo_hysteresis), effects, energy, method, float(rtol) if adaptive else math.nan,
        float(atol) if adaptive else math.nan))
    if not result.complete:
        raise interrupted(f"simulate interrupted at t = {result.t[-1]:g} s (the trajectory up to there is in "
                          "the exception's .partial, complete False, no final_state)", partial=result)
    if out.get("interrupted", False):  # Ctrl-C as the run ended: the engine kept it for this result
        raise interrupted(f"simulate interrupted as its run ended at t = {result.t[-1]:g} s (the whole result is "
                          "in the exception's .partial)", partial=result)
    return result

