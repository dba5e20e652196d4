"""Measured friction rigs: load a record (``data.py``), prepare its rows (``regressors.py``,
one per rig, shared by the next two), identify the rig and judge the fit (``fit.py``,
``idm-rs rig-fit``), diagnose what its identified model misses (``diagnosis.py``, ``idm-rs
diagnose FILE.mat``), and draw both (``plots.py``). ``signals.py`` holds the signal helpers."""

from .data import RealDataError, RigData, load
from .diagnosis import RigCandidate, RigDiagnosis, diagnose_rig
from .fit import RigFit, judge, rig_fit
from .plots import plot_rig_diagnosis, plot_rig_fit

__all__ = ["RealDataError", "RigCandidate", "RigData", "RigDiagnosis", "RigFit", "diagnose_rig", "judge", "load",
           "plot_rig_diagnosis", "plot_rig_fit", "rig_fit"]
