"""How a run is integrated, as one object every entry point takes (``solver=``), as diffrax
passes a solver and its step-size controller: the method, the fixed step or the tolerances, the
first trial step and the retries of a diverging fixed-step point.

``simulate``, ``sweep``, ``characterize``, ``batch.run``/``batch.start`` and ``diagnose`` take
``solver=Solver(...)``; each also keeps its flat keywords (``method=``, ``dt=``, ...). Giving
both is refused when they disagree, so a setting is never silently dropped.

>>> from idm_rs import Solver
>>> Solver("dopri5", rtol=1e-8).rtol
1e-08
"""

from __future__ import annotations

import math
from dataclasses import dataclass, fields
from typing import Any, Optional

from . import methods
from .methods import MethodName

#: the keywords a Solver stands for, in the order of its fields
SOLVER_KEYWORDS: tuple[str, ...] = ("method", "dt", "rtol", "atol", "first_step", "retries")


@dataclass(frozen=True)
class Solver:
    """How to integrate.

    Parameters
    ----------
    method : {"rk4", "dopri5", "rodas4", "auto"}
        ``"rk4"``: fixed step ``dt``; the others choose their steps from ``rtol``/``atol``
        (:mod:`idm_rs.core.methods`).
    dt : float, optional
        RK4 step [s]; None: the entry point's default.
    rtol, atol : float, optional
        Relative and absolute tolerances of an adaptive method (``atol`` in units of each state's
        natural scale); None: the method's default (``"auto"``: its measured 1 nm setting).
    first_step : float, optional
        First trial step of an adaptive method [s].
    retries : int, optional
        Retries of a diverging fixed-step point at dt/2, dt/4, ... (sweeps and batches); None:
        the entry point's default.
    """

    method: MethodName = "rk4"
    dt: Optional[float] = None
    rtol: Optional[float] = None
    atol: Optional[float] = None
    first_step: Optional[float] = None
    retries: Optional[int] = None

    def __post_init__(self) -> None:
        methods.check(self.method)
        for name in ("dt", "rtol", "atol", "first_step"):
            v = getattr(self, name)
            if v is not None and not (isinstance(v, (int, float)) and math.isfinite(v) and v > 0):
                raise ValueError(f"Solver: '{name}' must be a positive finite number or None; got {v!r}")
        if self.retries is not None and not (isinstance(self.retries, int) and self.retries >= 0):
            raise ValueError(f"Solver: 'retries' must be a non-negative integer or None; got {self.retries!r}")
        if self.dt is not None and methods.is_adaptive(self.method):
            raise ValueError(f"Solver: method {self.method!r} chooses its own steps and takes no 'dt'; give "
                             "rtol/atol (or method='rk4' with dt)")

    def keywords(self) -> dict[str, Any]:
        """The flat keywords it stands for, without those left at None."""
        return {f.name: getattr(self, f.name) for f in fields(self) if getattr(self, f.name) is not None}


def resolve_solver(solver: Optional[Solver], given: dict[str, Any], defaults: dict[str, Any],
                   where: str) -> dict[str, Any]:
    """The solver keywords an entry point runs with: ``given`` (its flat keywords as called) where
    ``solver`` is None; else ``solver``'s, refusing a flat keyword set to something other than
    its default (``defaults``) and other than the solver's. ``where`` names the entry point."""
    if solver is None:
        return dict(given)
    if not isinstance(solver, Solver):
        raise TypeError(f"{where}: 'solver' must be an idm_rs.Solver; got {type(solver).__name__}")
    out = dict(given)
    for name, value in solver.keywords().items():
        if name not in given:
            raise ValueError(f"{where} takes no '{name}' (solver.{name} = {value!r}); leave it at None")
        if given[name] != defaults.get(name) and given[name] != value:
            raise ValueError(f"{where}: '{name}' is given as {given[name]!r} and as solver.{name} = {value!r}; "
                             "give it once")
        out[name] = value
    return out
