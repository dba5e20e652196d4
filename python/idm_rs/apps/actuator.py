"""Actuator characteristics: the curves a designer judges a stick-slip drive by.

* :func:`steady_state` — over a sawtooth train, after ``skip_cycles`` start-up cycles: mean
  velocity [m/s], step per cycle [m] (mean and spread), back-slip per cycle [m] and its ratio to
  the cycle's reach, and whether the body moves forward, backward or stalls. The same numbers
  are sweep metrics (``sweep(..., grid={"frequency": ..., "voltage": ...})`` gives the velocity
  map) and :meth:`idm_rs.SimulationResult.steady_state`.
* :func:`stall_force` — the external load on the main body (``Params.load_force``, opposing the
  motion) at which the mean velocity falls to zero, by a bracketing root search.
* :func:`characterize` — the standard set: velocity against frequency at several voltages, step
  and back-slip against voltage, velocity against load with the stall force marked, as one
  ``xarray.Dataset`` (:func:`plot_characteristics` draws it; ``idm-rs characterize`` does both).

Definitions (per cycle k, x1 the main body's position, cycle boundaries the starts of the
sawtooth periods, which every integrator lands on): step_k = x1(end) − x1(start); the travel
forward and backward within the cycle are summed over the integrator's steps (so step = forward
travel − backward travel, whatever order the motions come in); back-slip_k = the travel against
the net direction, and the ratio is Σ back-slip / Σ travel along it. The motion counts as
stalled when |mean step| < 1e-3 · d33 · V (a thousandth of the free stroke). A light weight at a
fast edge can move a device *backward* under a "forward" sawtooth: the direction says so.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from pathlib import Path
from typing import TYPE_CHECKING, Any, Iterable, Optional, Sequence, Union, cast

import numpy as np
from numpy.typing import NDArray

from ..core import options
from ..core.declarations import Model, elements_of
from ..core.effects import Effects
from ..core.interrupted import interrupted, partial_result
from ..core.methods import MethodName
from ..core.params import Params
from ..core.solver import Solver, resolve_solver
from ..core.steady_state import STEADY_METRICS, SteadyState, check_train, run_trains, steady_of, steady_state
from ..core.units import si
from ..core.waveforms import STARTUP_CYCLES, Sawtooth

if TYPE_CHECKING:
    import xarray

#: the designer's curves, the steady state of one train (core.steady_state) among them
__all__ = ["STEADY_METRICS", "StallForce", "SteadyState", "characterize", "plot_characteristics", "stall_force",
           "steady_state"]

#: numbers given as a sequence or a float array
Floats = Union[Sequence[float], NDArray[np.float64]]

#: the stall force is bracketed to this share of the static friction force mu_s Fn
STALL_XTOL_FRACTION = 1e-3


@dataclass(frozen=True)
class StallForce:
    """The load at which the actuator stalls, and the curve that located it."""

    force: float  #: magnitude of the opposing load at zero mean velocity [N] (NaN if not bracketed)
    loads: np.ndarray  #: opposing loads tried [N] (>= 0), ascending
    velocities: np.ndarray  #: mean velocity at each load [m/s]
    xtol: float  #: bracket width at the end [N]
    direction: float  #: the unloaded motion's direction (+1 or -1)

    def __str__(self) -> str:
        if not math.isfinite(self.force):
            return (f"StallForce(not bracketed: the mean velocity kept its sign up to {si(float(self.loads[-1]), 'N')}"
                    " of opposing load)")
        return (f"StallForce({si(self.force, 'N')} ± {si(self.xtol / 2, 'N', 2)}: the opposing load on the main "
                f"body at zero mean velocity; unloaded {si(float(self.velocities[0]), 'm/s')})")


def stall_force(params: Params, waveform: Sawtooth, *, model: Model = "dps", n_elements: Optional[int] = None,
                effects: Optional[Effects] = None, skip_cycles: int = STARTUP_CYCLES, method: MethodName = "auto",
                loads: int = 9, xtol: Optional[float] = None, threads: Optional[int] = None,
                **how: Any) -> StallForce:
    """The opposing load on the main body at which the mean velocity reaches zero.

    The load acts against the unloaded motion (``load_force`` = −F for a forward drive). A coarse
    curve of ``loads`` points from 0 to 1.5 μs·Fn (beyond the static friction force, where the
    body cannot hold the load at all) runs as one parallel batch; the first sign change of the
    mean velocity is then narrowed by :func:`scipy.optimize.brentq` to ``xtol`` [N] (default
    ``STALL_XTOL_FRACTION`` · μs·Fn), each evaluation one steady-state run. NaN when the unloaded
    drive stalls or the curve never changes sign.

    Parameters
    ----------
    params : Params
        The device (its ``load_force`` is the load's starting point).
    waveform : Sawtooth
        The drive train.
    model, n_elements, effects, skip_cycles, method, threads
        As for :func:`steady_state`.
    loads : int
        Points of the coarse curve (>= 3).
    xtol : float, optional
        Width of the final bracket [N].

    Returns
    -------
    StallForce
        ``force`` [N] (NaN when not bracketed), the coarse curve ``loads`` [N] and
        ``velocities`` [m/s], ``xtol`` [N] and the unloaded ``direction``.

    Examples
    --------
    >>> from idm_rs.apps.actuator import stall_force
    >>> f = stall_force(idm_rs.Params(), idm_rs.Sawtooth(amplitude=80.0, frequency=100.0, cycles=6),
    ...                 model="lps")  # doctest: +SKIP
    >>> print(f)  # doctest: +SKIP
    StallForce(558 mN ± ...)
    """
    from scipy.optimize import brentq

    n_elements = options.elements(model, n_elements)
    check_train(waveform, skip_cycles)
    loads = options.count("loads", loads, minimum=3)
    fs = max(params.mu_s, params.mu_k) * params.effective_normal_force
    xtol = float(xtol) if xtol is not None else STALL_XTOL_FRACTION * fs
    kw = dict(model=model, n_elements=n_elements, effects=effects, skip_cycles=skip_cycles, method=method,
              threads=threads, **how)
    base = params.load_force

    def velocities(forces: Iterable[float], sign: float) -> np.ndarray:
        ps = [replace(params, load_force=base - sign * f) for f in forces]
        out = run_trains(ps, [waveform] * len(ps), **kw)
        return np.array([steady_of(out, i).mean_velocity for i in range(len(ps))])

    v0 = velocities([0.0], 1.0)[0]
    sign = float(np.sign(v0)) if np.isfinite(v0) else 0.0
    grid = np.linspace(0.0, 1.5 * fs, int(loads))
    if sign == 0.0:
        return StallForce(math.nan, grid, np.full(grid.size, math.nan), xtol, 0.0)
    v = velocities(grid, sign)
    v[0] = v0
    crossing = np.flatnonzero(np.sign(v[1:]) * sign <= 0)
    if crossing.size == 0:
        return StallForce(math.nan, grid, v, xtol, sign)
    j = int(crossing[0])
    a, b = float(grid[j]), float(grid[j + 1])
    if v[j + 1] == 0.0:
        return StallForce(b, grid, v, 0.0, sign)
    force = brentq(lambda f: float(velocities([f], sign)[0]), a, b, xtol=xtol)
    return StallForce(float(force), grid, v, xtol, sign)


def characterize(params: Optional[Params] = None, *, model: Model = "dps", n_elements: Optional[int] = None,
                 effects: Optional[Effects] = None, frequencies: Optional[Floats] = None,
                 voltages: Floats = (40.0, 60.0, 80.0, 100.0, 120.0),
                 step_voltages: Optional[Floats] = None, frequency: float = 100.0,
                 voltage: float = 80.0, rise: float = 0.5e-3, cycles: int = 6, skip_cycles: int = STARTUP_CYCLES,
                 loads: int = 9, method: MethodName = "auto", threads: Optional[int] = None,
                 progress: bool = True, solver: Optional[Solver] = None) -> "xarray.Dataset":
    """The standard characteristics of a design as one Dataset.

    * ``mean_velocity(voltage, frequency)`` and the other steady-state metrics over the
      frequency × voltage grid (``frequencies`` default: 12 log-spaced from 20 Hz to the highest
      frequency the ``rise`` allows with a 10 % margin, at most 1.5 kHz);
    * ``step_mean(step_voltage)``, ``backslip(step_voltage)``, ``backslip_ratio(step_voltage)`` at
      ``frequency`` (``step_voltages`` default: 11 from 20 to 120 V);
    * ``stall_force`` (attribute and variable) by :func:`stall_force`, and ``load_velocity(load)``
      at (``frequency``, ``voltage``) from no load to 1.5 x the stall force (the coarse bracket's
      curve when no stall was found).

    Every run is a sawtooth train of ``cycles`` periods with the fast edge ``rise`` [s]; the
    first ``skip_cycles`` are start-up. Defaults suit the paper's device (Table 1).

    Ctrl-C raises a ``KeyboardInterrupt`` whose ``partial`` is a Dataset of the curves as
    far as they ran (NaN where not, no stall force, ``attrs["complete"] == 0``).

    Parameters
    ----------
    params : Params, optional
        The device (default: the paper's).
    model : {"lps", "dps"}
        The structure; ``n_elements`` FEM elements for the DPS (default 4).
    effects : Effects, optional
        Extra physics of the catalogue.
    frequencies, voltages : arrays [Hz], [V]
        The velocity map's grid.
    step_voltages : array [V], optional
        The step curve's amplitudes (at ``frequency``).
    frequency, voltage : float [Hz], [V]
        The design point of the step curve and the load curve.
    rise : float
        The sawtooth's fast edge [s].
    cycles, skip_cycles : int
        Periods per run, and the start-up ones left out of the steady state.
    loads : int
        Loads of the stall force's first bracket (>= 3).
    method : str
        The integrator (default ``"auto"``).
    threads : int, optional
        Threads (default: every core).
    progress : bool
        Progress bars, one per curve.
    solver : Solver, optional
        The method and its settings for every run (:class:`idm_rs.Solver`); refused where
        ``method`` says otherwise.

    Returns
    -------
    xarray.Dataset
        ``mean_velocity(voltage, frequency)`` [m/s] and the other steady-state metrics,
        ``step_mean`` / ``backslip`` ... ``_vs_voltage`` [m], ``load_velocity(load)`` [m/s],
        ``stall_force`` [N]; the design point in the attributes.

    Examples
    --------
    >>> from idm_rs.apps.actuator import characterize
    >>> ds = characterize(model="lps", progress=False)   # doctest: +SKIP
    >>> float(ds["stall_force"])                          # [N]   # doctest: +SKIP
    """
    import xarray as xr

    from ..core.engine import __version__
    from ..sweeps.sweep import sweep

    n_elements = options.elements(model, n_elements)
    params = params or Params()
    loads = options.count("loads", loads, minimum=3)
    threads = options.threads(threads)
    if frequencies is None:
        f_max = min(1500.0, 0.9 / (2.0 * rise))
        frequencies = np.geomspace(20.0, f_max, 12)
    step_voltages = np.linspace(20.0, 120.0, 11) if step_voltages is None else step_voltages
    train = Sawtooth(amplitude=voltage, frequency=frequency, cycles=cycles, rise=rise)
    check_train(train, skip_cycles)
    unset = dict.fromkeys(("dt", "rtol", "atol", "first_step", "retries"))
    how = resolve_solver(solver, dict(method=method, **unset), dict(method="auto", **unset), "characterize")
    method = how.pop("method")
    extra = {k: v for k, v in how.items() if v is not None}  # what a Solver set beside the method
    common: dict[str, Any] = dict(model=model, n_elements=n_elements, effects=effects, method=method,
                                  threads=threads, skip_cycles=skip_cycles, **extra)
    done: dict[str, Any] = {}
    try:
        vmap = done["vmap"] = _kept(sweep, params, train, {"voltage": np.asarray(voltages, float),
                                                           "frequency": np.asarray(frequencies, float)},
                                    done, "vmap", **common, progress=progress and "characterize: velocity map")
        steps = done["steps"] = _kept(sweep, params, train, {"voltage": np.asarray(step_voltages, float)},
                                      done, "steps", **common, progress=progress and "characterize: step curve")
        stall = stall_force(params, train, model=model, n_elements=n_elements, effects=effects,
                            skip_cycles=skip_cycles, method=method, loads=loads, threads=threads, **extra)
        load_grid, load_v = stall.loads, stall.velocities
        if math.isfinite(stall.force) and stall.force > 0:
            # the curve a designer reads: from no load to past the stall, not the coarse bracket
            # (which runs to where the load drags the body backwards at speed)
            load_grid = np.linspace(0.0, 1.5 * stall.force, max(int(loads), 5))
            ps = [replace(params, load_force=params.load_force - stall.direction * f) for f in load_grid]
            out = run_trains(ps, [train] * len(ps), model=model, n_elements=n_elements, effects=effects,
                              skip_cycles=skip_cycles, method=method, threads=threads, **extra)
            load_v = np.array([steady_of(out, i).mean_velocity for i in range(len(ps))])
    except KeyboardInterrupt:
        partial = _interrupted(done, step_voltages, frequency, params, model, n_elements, rise, cycles, skip_cycles,
                               voltage)
        raise interrupted(f"characterize interrupted: kept {partial.attrs['kept']} (as far as it ran; NaN where "
                          "not), no stall force (the Dataset is the exception's .partial, attrs['complete'] = 0)",
                          partial=partial) from None
    ds: "xarray.Dataset" = xr.Dataset()
    for name in STEADY_METRICS:
        ds[name] = vmap[name]
    for name in ("step_mean", "step_std", "backslip", "backslip_ratio", "direction"):
        ds[f"{name}_vs_voltage"] = ("step_voltage", steps[name].values, steps[name].attrs)
    ds = ds.assign_coords(step_voltage=("step_voltage", np.asarray(step_voltages, float),
                                        {"units": "V", "long_name": f"drive amplitude (at {frequency:g} Hz)"}))
    ds["load_velocity"] = ("load", load_v, {"units": "m/s", "long_name": (
        f"mean velocity against an opposing load (at {frequency:g} Hz, {voltage:g} V)")})
    ds = ds.assign_coords(load=("load", load_grid, {"units": "N", "long_name": "opposing load on the main body"}))
    ds["stall_force"] = ((), stall.force, {"units": "N", "long_name": "opposing load at zero mean velocity",
                                           "xtol_N": stall.xtol})
    ds.attrs.update({
        "idm_rs_version": __version__, "model": model, "n_elements": elements_of(model, n_elements),
        "method": vmap.attrs["method"], "rise_s": rise, "cycles": cycles, "skip_cycles": skip_cycles,
        "design_frequency_Hz": frequency, "design_voltage_V": voltage,
        "velocity_at_design_m_per_s": float(ds["load_velocity"].values[0]),
        "stall_force_N": stall.force, "complete": 1,
    })
    for name, value in params.to_dict(resolved=False).items():
        ds.attrs[f"param_{name}"] = value if value is not None else "derived"
    return ds


def _kept(sweep: Any, params: Params, train: Sawtooth, grid: dict[str, Any], done: dict[str, Any], key: str,
          **common: Any) -> "xarray.Dataset":
    """``sweep(params, train, grid, **common)``; on Ctrl-C its finished points go into
    ``done[key]`` before the interrupt travels on."""
    try:
        return cast("xarray.Dataset", sweep(params, train, grid, **common))
    except KeyboardInterrupt as stop:
        if partial_result(stop) is not None:
            done[key] = partial_result(stop)
        raise


def _interrupted(done: dict[str, Any], step_voltages: Any, frequency: float, params: Params, model: str,
                 n_elements: int, rise: float, cycles: int, skip_cycles: int, voltage: float) -> "xarray.Dataset":
    """What ``characterize`` had finished when Ctrl-C stopped it: the velocity map and the
    step curve as far as they ran (NaN where not), no stall force; ``attrs["complete"]`` 0."""
    import xarray as xr

    from ..core.engine import __version__

    ds = xr.Dataset()
    if "vmap" in done:
        for name in STEADY_METRICS:
            ds[name] = done["vmap"][name]
    if "steps" in done:
        for name in ("step_mean", "step_std", "backslip", "backslip_ratio", "direction"):
            ds[f"{name}_vs_voltage"] = ("step_voltage", done["steps"][name].values, done["steps"][name].attrs)
        ds = ds.assign_coords(step_voltage=("step_voltage", np.asarray(step_voltages, float),
                                            {"units": "V", "long_name": f"drive amplitude (at {frequency:g} Hz)"}))
    kept = ", ".join({"vmap": "the velocity map", "steps": "the step curve"}[k] for k in done) or "nothing"
    ds.attrs.update({
        "idm_rs_version": __version__, "model": model, "n_elements": elements_of(model, n_elements),
        "rise_s": rise, "cycles": cycles, "skip_cycles": skip_cycles, "design_frequency_Hz": frequency,
        "design_voltage_V": voltage, "velocity_at_design_m_per_s": math.nan, "stall_force_N": math.nan,
        "complete": 0, "kept": kept,
    })
    for name, value in params.to_dict(resolved=False).items():
        ds.attrs[f"param_{name}"] = value if value is not None else "derived"
    return ds


def plot_characteristics(ds: "xarray.Dataset", out_dir: Path) -> list[Path]:
    """Three PNGs in ``out_dir``: velocity vs frequency per voltage, step and back-slip vs
    voltage, velocity vs load with the stall force marked."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    a = ds.attrs
    paths = []
    fig, ax = plt.subplots(figsize=(6.4, 4.4), constrained_layout=True)
    for v in ds["voltage"].values:
        ax.plot(ds["frequency"].values, ds["mean_velocity"].sel(voltage=v).values * 1e3, marker="o", ms=3,
                label=f"{v:g} V")
    ax.set_xscale("log")
    ax.axhline(0.0, color="0.5", lw=0.8)
    ax.set_xlabel("drive frequency [Hz]")
    ax.set_ylabel("mean velocity [mm/s]")
    ax.set_title(f"velocity vs frequency (rise {a['rise_s'] * 1e3:g} ms, {a['model'].upper()})", fontsize=10)
    ax.legend(title="amplitude", fontsize=8, loc="upper left", bbox_to_anchor=(1.0, 1.0))  # beside the curves
    ax.grid(alpha=0.3, which="both")
    paths.append(out_dir / "velocity_vs_frequency.png")
    fig.savefig(paths[-1], dpi=130)
    plt.close(fig)

    fig, ax = plt.subplots(figsize=(6.4, 4.4), constrained_layout=True)
    v = ds["step_voltage"].values
    ax.plot(v, ds["step_mean_vs_voltage"].values * 1e9, marker="o", label="step per cycle")
    ax.fill_between(v, (ds["step_mean_vs_voltage"] - ds["step_std_vs_voltage"]).values * 1e9,
                    (ds["step_mean_vs_voltage"] + ds["step_std_vs_voltage"]).values * 1e9, alpha=0.2)
    ax.plot(v, ds["backslip_vs_voltage"].values * 1e9, marker="s", label="back-slip per cycle")
    ax.set_xlabel("drive amplitude [V]")
    ax.set_ylabel("per cycle [nm]")
    ax2 = ax.twinx()
    ax2.plot(v, ds["backslip_ratio_vs_voltage"].values, color="0.4", ls="--", label="back-slip ratio")
    ax2.set_ylabel("back-slip ratio [-]")
    ax.set_title(f"step and back-slip at {a['design_frequency_Hz']:g} Hz", fontsize=10)
    lines = ax.get_legend_handles_labels()
    lines2 = ax2.get_legend_handles_labels()
    # above the axes: inside, it covered the back-slip peak at 40 V
    ax.legend(lines[0] + lines2[0], lines[1] + lines2[1], fontsize=8, loc="lower center", bbox_to_anchor=(0.5, 1.08),
              ncol=3, frameon=False)
    ax.grid(alpha=0.3)
    paths.append(out_dir / "step_backslip_vs_voltage.png")
    fig.savefig(paths[-1], dpi=130)
    plt.close(fig)

    fig, ax = plt.subplots(figsize=(6.4, 4.4), constrained_layout=True)
    ax.plot(ds["load"].values, ds["load_velocity"].values * 1e3, marker="o")
    ax.axhline(0.0, color="0.5", lw=0.8)
    stall = float(ds["stall_force"])
    if np.isfinite(stall):
        ax.axvline(stall, color="C3", ls="--", label=f"stall force {stall:.3g} N")
        ax.legend(fontsize=8)
    ax.set_xlabel("opposing load on the main body [N]")
    ax.set_ylabel("mean velocity [mm/s]")
    ax.set_title(f"load curve at {a['design_frequency_Hz']:g} Hz, {a['design_voltage_V']:g} V", fontsize=10)
    ax.grid(alpha=0.3)
    paths.append(out_dir / "velocity_vs_load.png")
    fig.savefig(paths[-1], dpi=130)
    plt.close(fig)
    return paths
