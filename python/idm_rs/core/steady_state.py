"""Steady-state metrics of a sawtooth train (the actuator's figures of merit over its full
cycles after the start-up): mean velocity [m/s], step per cycle [m] (mean and spread), back-slip
per cycle [m] and its ratio to the cycle's reach, and the direction of motion. The same numbers
are sweep metrics and :meth:`idm_rs.SimulationResult.steady_state`; the curves built on them
(stall force, characteristics) are :mod:`idm_rs.apps.actuator`'s.

Definitions (per cycle k, x1 the main body's position, cycle boundaries the starts of the
sawtooth periods, which every integrator lands on): step_k = x1(end) − x1(start); the travel
forward and backward within the cycle are summed over the integrator's steps (so step = forward
travel − backward travel, whatever order the motions come in); back-slip_k = the travel against
the net direction, and the ratio is Σ back-slip / Σ travel along it. The motion counts as
stalled when |mean step| < 1e-3 · d33 · V (a thousandth of the free stroke)."""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Optional, Sequence

from . import options
from .batch import Point, Structure, run
from .declarations import Model
from .effects import Effects
from .methods import MethodName
from .params import Params
from .units import si
from .waveforms import STARTUP_CYCLES, Sawtooth

#: steady-state metric -> (units, meaning)
STEADY_METRICS: dict[str, tuple[str, str]] = {
    "mean_velocity": ("m/s", "mean velocity of the main body (mean step x frequency)"),
    "step_mean": ("m", "mean step per cycle"),
    "step_std": ("m", "standard deviation of the step over the cycles"),
    "backslip": ("m", "mean back-slip per cycle: travel against the net direction"),
    "backslip_ratio": ("1", "back-slip over the travel along the net direction"),
    "direction": ("1", "+1 forward, -1 backward, 0 stalled"),
}


@dataclass(frozen=True)
class SteadyState:
    """Steady-state metrics of one sawtooth train (NaN when no full cycle was averaged)."""

    mean_velocity: float  #: [m/s]
    step_mean: float  #: [m]
    step_std: float  #: [m]
    backslip: float  #: [m]
    backslip_ratio: float  #: [-]
    direction: float  #: +1, -1, 0 (stalled), NaN

    @property
    def motion(self) -> str:
        """"forward", "backward", "stalled" or "unknown"."""
        return {1.0: "forward", -1.0: "backward", 0.0: "stalled"}.get(self.direction, "unknown")

    def __str__(self) -> str:
        return (f"SteadyState({self.motion}: mean velocity {si(self.mean_velocity, 'm/s')}, step "
                f"{si(self.step_mean, 'm')} ± {si(self.step_std, 'm')} per cycle, back-slip {si(self.backslip, 'm')} "
                f"per cycle ({self.backslip_ratio:.3g} of the travel along the net direction))")


def check_train(waveform: Any, skip_cycles: int) -> Sawtooth:
    if not isinstance(waveform, Sawtooth):
        raise ValueError(f"steady-state metrics need a Sawtooth train, got {type(waveform).__name__}")
    options.skip_cycles(skip_cycles, waveform.cycles)
    return waveform


def run_trains(params: Sequence[Params], waves: Sequence[Sawtooth], *, model: Model, n_elements: int,
                effects: Optional[Effects], skip_cycles: int, method: MethodName, threads: Optional[int],
                piezo_hysteresis: bool = True, t_end: Optional[float] = None, **how: Any) -> dict[str, Any]:
    """One batch of trains (each point to its own train's end, or to ``t_end``)."""
    from ..core import methods

    method_name, rtol, atol = methods.resolve(method, how.pop("rtol", None), how.pop("atol", None))
    effects = effects or Effects()
    points = [Point(p, effects, w, t_end=t_end or w.duration) for p, w in zip(params, waves)]
    longest = max(pt.t_end for pt in points if pt.t_end is not None)  # every point has one
    return run(points, Structure(model, int(n_elements), bool(piezo_hysteresis)),
               t_end=longest, method=method_name, rtol=rtol, atol=atol, skip_cycles=int(skip_cycles),
               threads=threads, **how)


def steady_of(out: dict[str, Any], i: int) -> SteadyState:
    if int(out["status"][i]) not in (1, 2):
        return SteadyState(*(math.nan,) * 6)
    return SteadyState(*(float(out[k][i]) for k in STEADY_METRICS))


def steady_state(params: Params, waveform: Sawtooth, *, model: Model = "dps", n_elements: Optional[int] = None,
                 effects: Optional[Effects] = None, skip_cycles: int = STARTUP_CYCLES, method: MethodName = "auto",
                 threads: Optional[int] = None, piezo_hysteresis: bool = True, t_end: Optional[float] = None,
                 **how: Any) -> SteadyState:
    """Steady-state metrics of ``params`` driven by the sawtooth train ``waveform`` (to its end,
    or to ``t_end`` [s]), averaged over its full cycles after the first ``skip_cycles``.
    ``method`` (default ``"auto"``) and ``how`` (``dt`` for RK4, ``rtol``/``atol``/``first_step``
    for adaptive methods) as in :func:`idm_rs.sweeps.sweep`. A run that diverges gives NaN metrics.

    Parameters
    ----------
    params : Params
        The device.
    waveform : Sawtooth
        The drive train ([V], [Hz], its fast edge ``rise`` [s]).
    model : {"lps", "dps"}
        The structure; ``n_elements`` FEM elements for the DPS (default 4).
    effects : Effects, optional
        Extra physics of the catalogue.
    skip_cycles : int
        Start-up cycles left out (fewer than the train's cycles).
    method : str
        The integrator (default ``"auto"``).
    t_end : float, optional
        End of the run [s] (default: the train's end).

    Returns
    -------
    SteadyState
        ``mean_velocity`` [m/s], ``step_mean`` and ``step_std`` [m] per cycle, ``backslip`` [m]
        per cycle, ``backslip_ratio``, ``direction`` (+1, -1, 0 stalled).

    Examples
    --------
    >>> from idm_rs.apps.actuator import steady_state
    >>> s = steady_state(idm_rs.Params(), idm_rs.Sawtooth(amplitude=80.0, frequency=100.0, cycles=6), model="lps")
    >>> s.motion
    'forward'
    """
    n_elements = options.elements(model, n_elements)
    check_train(waveform, skip_cycles)
    out = run_trains([params], [waveform], model=model, n_elements=n_elements, effects=effects,
                      skip_cycles=skip_cycles, method=method, threads=threads, piezo_hysteresis=piezo_hysteresis,
                      t_end=t_end, **how)
    return steady_of(out, 0)
