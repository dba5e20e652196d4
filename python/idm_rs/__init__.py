"""idm-rs: dynamics of piezoelectric impact drive mechanisms (stick-slip inertial actuators).

A Rust core (fixed-step RK4 over the nodal state, Leuven friction, Bouc-Wen hysteresis) under a
typed Python API. Quick start::

    import idm_rs
    p = idm_rs.Params()                                   # the paper's Table 1
    w = idm_rs.Triangle(amplitude=80.0, rise=0.5e-3, fall=9.5e-3)
    r = idm_rs.simulate(p, w, t_end=10e-3, dt=1e-8, model="dps", n_elements=4)
    r.final_position                                      # x1(10 ms) [m]
"""

from . import methods
from .diagnosis import Diagnosis, diagnose, plot_diagnosis, text_report
from .effects import Effects
from .engine import __version__
from .external_force import ExternalForce
from .interrupted import partial_result
from .params import Params
from .recording import Recording, RecordingError, load_case
from .simulation import DivergenceError, EnergyBudget, SimulationResult, simulate
from .solver import Solver
from .state import State
from .sweep import sweep
from .sweep_plan import METRICS
from .waveforms import Sampled, Sawtooth, Triangle, Waveform

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
