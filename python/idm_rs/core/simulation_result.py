"""The result of one simulation (:class:`SimulationResult`: the saved trajectory, its
derived quantities, its steady state and its xarray form) and its energy accounting
(:class:`EnergyBudget`)."""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any, Optional

import numpy as np
from numpy.typing import NDArray

from . import methods
from .declarations import structure_label
from .effects import Effects
from .params import PARAM_INFO, Params
from .state import State
from .steady_state import SteadyState, steady_state
from .waveforms import STARTUP_CYCLES, Waveform

if TYPE_CHECKING:
    import xarray


@dataclass(frozen=True)
class EnergyBudget:
    """Energy and momentum accounting integrated with the state (all per saved time).

    Energies in J: ``kinetic`` ½vᵀMv, ``strain`` ½qᵀKq, ``input_work`` ∫Fp(v1 − v_weight)dt,
    ``friction_work`` ∫Ff v1 dt, ``damping_work`` ∫vᵀCv dt, ``external_work`` (effects' forces).
    Impulses in N·s: ``momentum`` 1ᵀMv [kg m/s], ``friction_impulse`` ∫Ff dt,
    ``rayleigh_impulse`` αc∫1ᵀMp v dt, ``external_impulse``.
    """

    kinetic: NDArray[np.float64]
    strain: NDArray[np.float64]
    input_work: NDArray[np.float64]
    friction_work: NDArray[np.float64]
    damping_work: NDArray[np.float64]
    external_work: NDArray[np.float64]
    momentum: NDArray[np.float64]
    friction_impulse: NDArray[np.float64]
    rayleigh_impulse: NDArray[np.float64]
    external_impulse: NDArray[np.float64]

    @property
    def residual(self) -> NDArray[np.float64]:
        """Stored energy minus net work in [J]; zero up to the integrator's error."""
        return self.kinetic + self.strain - (
            self.input_work - self.friction_work - self.damping_work + self.external_work
        )

    @property
    def relative_residual(self) -> float:
        """max |residual| over the largest energy flow of the run [-]."""
        scale = max(
            float(np.max(np.abs(a)))
            for a in (self.input_work, self.friction_work, self.damping_work, self.kinetic + self.strain)
        )
        return float(np.max(np.abs(self.residual)) / scale) if scale > 0 else 0.0

    @property
    def momentum_residual(self) -> NDArray[np.float64]:
        """1ᵀMv + ∫Ff dt + αc∫1ᵀMp v dt − ∫F_ext dt [N s]; zero up to the integrator's error."""
        return self.momentum + self.friction_impulse + self.rayleigh_impulse - self.external_impulse


@dataclass(frozen=True)
class SimulationResult:
    """A saved trajectory. Arrays have one entry per saved time (``save_every`` steps apart,
    plus t = 0 and t_end); ``nodes`` and ``velocities`` have one column per node (node 0 is the
    main body at z = l, the last the weight at z = 0)."""

    t: NDArray[np.float64]
    """time [s]"""
    nodes: NDArray[np.float64]
    """nodal displacements [m], shape (time, node)"""
    velocities: NDArray[np.float64]
    """nodal velocities [m/s]"""
    friction: NDArray[np.float64]
    """friction force Ff on the main body [N]"""
    fh: NDArray[np.float64]
    """presliding (hysteresis) friction force Fh [N]"""
    g: NDArray[np.float64]
    """asperity deformation g [m]"""
    h: NDArray[np.float64]
    """piezo hysteresis state h [m]"""
    voltage: NDArray[np.float64]
    """commanded voltage [V]"""
    piezo_force: NDArray[np.float64]
    """piezo force Fp [N]"""
    reading: NDArray[np.float64]
    """what the sensor reads [m] (x1 unless a sensor effect is on)"""
    final_position: float
    """x1(t_end) [m]"""
    params: Params
    """the device simulated"""
    waveform: Waveform
    """the drive"""
    model: str
    """the structure: "lps", "dps" or the rig's name"""
    n_elements: int
    """FEM elements (1 for the LPS)"""
    dt: float
    """RK4 step, or the first step of an adaptive run [s]"""
    piezo_hysteresis: bool
    """whether the PE force had its hysteresis"""
    effects: Effects
    """the catalogue's extra physics that were on"""
    energy: Optional[EnergyBudget] = None
    """the energy and momentum budgets (``simulate(..., energy=True)``), else None"""
    final_state: State = field(default_factory=lambda: State([], []), repr=False)
    """the state at t_end; pass it as ``initial_state`` (with ``t_start=t_end``) to continue"""
    method: str = "rk4"
    """the integrator that ran: "rk4", "dopri5" or "rodas4" (what "auto" resolved to)"""
    rtol: float = math.nan
    """the adaptive method's relative tolerance (NaN for RK4)"""
    atol: float = math.nan
    """the adaptive method's absolute tolerance, in each state's natural scale (NaN for RK4)"""
    complete: bool = True
    """False when Ctrl-C stopped the run: the arrays end where it stopped (``final_state`` empty)"""
    sensitivity_names: tuple[str, ...] = ()
    """the names whose derivatives were asked for (``simulate(..., sensitivities=...)``)"""
    sensitivities: NDArray[np.float64] = field(default_factory=lambda: np.zeros((0, 0)), repr=False)
    """d reading / d name, shape (time, name) [m per unit of the name]"""
    final_state_sensitivities: NDArray[np.float64] = field(default_factory=lambda: np.zeros((0, 0)), repr=False)
    """d final_state / d name, shape (state component, name)"""

    def __repr__(self) -> str:
        """A one-line summary (the arrays are attributes: ``result.t``, ``result.nodes``, ...)."""
        model = structure_label(self.model, self.n_elements)
        how = (f"{self.method}, rtol = {self.rtol:g}, atol = {self.atol:g}" if methods.is_adaptive(self.method)
               else f"{self.method}, dt = {self.dt:g} s")
        span = f"t = {self.t[0]:g}..{self.t[-1]:g} s" if self.t.size else "no saved times"
        on = self.effects.active()
        effects = f", effects {on}" if on else ""
        return (f"SimulationResult({model}, {self.waveform!r}, {how}, {span}, {self.t.size} saved times, "
                f"x1(end) = {self.final_position * 1e6:.6g} µm{effects}"
                f"{'' if self.complete else ', INCOMPLETE (interrupted)'})")

    def thinned(self, every: int) -> "SimulationResult":
        """Every ``every``-th saved time from the first, and the last: the result a run with
        ``save_every`` that many times larger saves (the same states, as the saved times of a
        run do not change its steps)."""
        if every == 1 or self.t.size == 0:
            return self
        keep = np.arange(0, self.t.size, every)
        if keep[-1] != self.t.size - 1:
            keep = np.append(keep, self.t.size - 1)
        n = self.t.size
        changes = {f.name: getattr(self, f.name)[keep] for f in dataclasses.fields(self)
                   if isinstance(getattr(self, f.name), np.ndarray) and getattr(self, f.name).shape[:1] == (n,)}
        if self.energy is not None:
            changes["energy"] = EnergyBudget(**{f.name: getattr(self.energy, f.name)[keep]
                                                for f in dataclasses.fields(self.energy)})
        return dataclasses.replace(self, **changes)

    def sensitivity(self, name: str) -> NDArray[np.float64]:
        """d ``reading`` / d ``name`` at every saved time [m per unit of ``name``]: the exact
        derivative of this discrete run (RK4 with its steps; an adaptive method with the steps
        it accepted held), computed by the engine in forward mode. ``name`` must be one of the
        ``sensitivities`` the run was asked for."""
        if name not in self.sensitivity_names:
            asked = ", ".join(self.sensitivity_names) or "none"
            raise ValueError(f"no sensitivity '{name}' in this result (asked for: {asked}); "
                             f"pass sensitivities=[..., '{name}'] to simulate()")
        return self.sensitivities[:, self.sensitivity_names.index(name)]

    @property
    def main_body(self) -> NDArray[np.float64]:
        """x1, main body displacement [m]."""
        return self.nodes[:, 0]

    @property
    def weight(self) -> NDArray[np.float64]:
        """x2, weight displacement [m]."""
        return self.nodes[:, -1]

    @property
    def main_body_velocity(self) -> NDArray[np.float64]:
        """v1 [m/s]."""
        return self.velocities[:, 0]

    def steady_state(self, skip_cycles: int = STARTUP_CYCLES) -> "SteadyState":
        """Steady-state actuator metrics of this run's sawtooth train (mean velocity, step and
        back-slip per cycle, direction; see :mod:`idm_rs.core.steady_state`), over its full cycles after
        the first ``skip_cycles``. Computed by the batch engine from the same settings (the
        saved samples may skip the extremes), so they equal a sweep's metrics for this point;
        a run continued from a state (``t_start`` > 0) is refused."""
        if self.t[0] != 0.0:
            raise ValueError("steady_state() re-runs the train from rest; this run started at "
                             f"t = {self.t[0]:g} s from a given state")
        how: dict[str, Any] = (
            {"rtol": self.rtol, "atol": self.atol, "first_step": self.dt} if methods.is_adaptive(self.method)
            else {"dt": self.dt})
        # ignores: this run's own waveform, model and method, typed wider than steady_state()'s; it
        # refuses a waveform that is not a Sawtooth train with a ValueError
        return steady_state(self.params, self.waveform, model=self.model, n_elements=self.n_elements,  # type: ignore[arg-type]
                            effects=self.effects, skip_cycles=skip_cycles, method=self.method,  # type: ignore[arg-type]
                            piezo_hysteresis=self.piezo_hysteresis, t_end=float(self.t[-1]), **how)

    def to_xarray(self) -> "xarray.Dataset":
        """The trajectory as an xarray Dataset with units, and every setting in ``attrs``."""
        import xarray as xr

        from .engine import __version__

        def var(data: NDArray[np.float64], units: str, long_name: str, dims: tuple[str, ...] = ("time",)
                ) -> "xarray.Variable":
            return xr.Variable(dims, data, {"units": units, "long_name": long_name})

        ds = xr.Dataset(
            {
                "main_body": var(self.main_body, "m", "main body displacement x1"),
                "weight": var(self.weight, "m", "weight displacement x2"),
                "nodes": var(self.nodes, "m", "nodal displacements", ("time", "node")),
                "velocities": var(self.velocities, "m/s", "nodal velocities", ("time", "node")),
                "friction": var(self.friction, "N", "friction force Ff"),
                "fh": var(self.fh, "N", "presliding friction force Fh"),
                "g": var(self.g, "m", "asperity deformation g"),
                "h": var(self.h, "m", "piezo hysteresis h"),
                "voltage": var(self.voltage, "V", "commanded voltage"),
                "piezo_force": var(self.piezo_force, "N", "piezo force Fp"),
                "reading": var(self.reading, "m", "sensor reading"),
            },
            coords={
                "time": ("time", self.t, {"units": "s", "long_name": "time"}),
                "node": ("node", np.arange(self.nodes.shape[1]), {"units": "1", "long_name": "node (0 = main body)"}),
            },
        )
        ds.attrs.update(
            {
                "idm_rs_version": __version__,
                "model": self.model,
                "n_elements": self.n_elements,
                "dt_s": self.dt,
                "method": self.method,
                "rtol": self.rtol,
                "atol": self.atol,
                "piezo_hysteresis": int(self.piezo_hysteresis),
                "waveform": repr(self.waveform),
                "final_position_m": self.final_position,
            }
        )
        if self.sensitivity_names:
            from .declarations import EFFECT_PARAMS, TABLE1

            units = {d.name: d.unit for d in (*TABLE1, *EFFECT_PARAMS)}
            units.update(dict(self.final_state.components))
            for k, name in enumerate(self.sensitivity_names):
                unit = units.get(name, "1")
                ds[f"d_reading_d_{name}"] = var(self.sensitivities[:, k], "m" if unit == "1" else f"m/({unit})",
                                                f"derivative of the sensor reading with respect to {name}")
        for name, value in self.params.to_dict().items():
            ds.attrs[f"param_{name}"] = value
            ds.attrs[f"param_{name}_units"] = PARAM_INFO[name][1]
        for name, value in self.effects.active().items():
            ds.attrs[f"effect_{name}"] = value
        return ds
