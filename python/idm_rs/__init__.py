"""idm-rs: dynamics of piezoelectric impact drive mechanisms (stick-slip inertial actuators).

A Rust core (fixed-step RK4 over the nodal state, Leuven friction, Bouc-Wen hysteresis) under a
typed Python API. Quick start::

    import idm_rs
    p = idm_rs.Params()                                   # the paper's Table 1
    w = idm_rs.Triangle(amplitude=80.0, rise=0.5e-3, fall=9.5e-3)
    r = idm_rs.simulate(p, w, t_end=10e-3, dt=1e-8, model="dps", n_elements=4)
    r.final_position                                      # x1(10 ms) [m]
"""

from .core import methods
from .core.effects import Effects
from .core.engine import __version__
from .core.external_force import ExternalForce
from .core.interrupted import partial_result
from .core.params import Params
from .core.simulation import DivergenceError, simulate
from .core.simulation_result import EnergyBudget, SimulationResult
from .core.solver import Solver
from .core.state import State
from .core.waveforms import Sampled, Sawtooth, Triangle, Waveform
from .diagnosis import Diagnosis, diagnose, plot_diagnosis, text_report
from .io.recording import Recording, RecordingError, load_case
from .sweeps.plan import METRICS
from .sweeps.sweep import sweep

__all__ = [
    "__version__",
    "methods",
    "Diagnosis",
    "DivergenceError",
    "Effects",
    "EnergyBudget",
    "ExternalForce",
    "Params",
    "Recording",
    "RecordingError",
    "Sampled",
    "Sawtooth",
    "SimulationResult",
    "Solver",
    "State",
    "Triangle",
    "Waveform",
    "METRICS",
    "diagnose",
    "load_case",
    "partial_result",
    "plot_diagnosis",
    "simulate",
    "sweep",
    "text_report",
]
