"""The library discovery regresses on: candidate force terms on the main body and on the weight
(the engine's ``library_force`` / ``library_force_weight`` coefficients, with how the report
prints them), and their columns along a simulated trajectory (computed by the engine)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Sequence

import numpy as np
from numpy.typing import NDArray


@dataclass(frozen=True)
class Term:
    """One library function: its engine coefficient, its symbol and what it reads."""

    param: str  #: the engine's effect parameter (its coefficient)
    symbol: str  #: as printed, e.g. "v1|v1|"
    unit: str  #: the coefficient's unit
    variable: str  #: the state it depends on, for the report ("x1", "v1", "x1 - x2", ...)
    periodic: bool = False


MAIN_TERMS: tuple[Term, ...] = (
    Term("lib_x1", "x1", "N/m", "x1"),
    Term("lib_v1", "v1", "N s/m", "v1"),
    Term("lib_dx", "x1 - x2", "N/m", "x1 - x2"),
    Term("lib_dv", "v1 - v2", "N s/m", "v1 - v2"),
    Term("lib_sgn", "sgn v1", "N", "v1"),
    Term("lib_abs", "|v1|", "N s/m", "v1"),
    Term("lib_vv", "v1|v1|", "N s^2/m^2", "v1"),
    Term("lib_volt", "V", "N/V", "V"),
    Term("lib_dvolt", "dV/dt", "N s/V", "V"),
    Term("lib_t", "t", "N/s", "t"),
    Term("lib_x1sq", "x1^2", "N/m^2", "x1"),
    Term("lib_x1cube", "x1^3", "N/m^3", "x1"),
    Term("lib_ff", "Ff", "1", "Ff"),
    Term("lib_sin", "sin(2 pi x1/lambda)", "N", "x1", True),
    Term("lib_cos", "cos(2 pi x1/lambda)", "N", "x1", True),
    Term("lib_ff_sin", "Ff sin(2 pi x1/lambda)", "1", "x1", True),
    Term("lib_ff_cos", "Ff cos(2 pi x1/lambda)", "1", "x1", True),
)


WEIGHT_TERMS: tuple[Term, ...] = (
    Term("libw_x2", "x2", "N/m", "x2"),
    Term("libw_v2", "v2", "N s/m", "v2"),
    Term("libw_dx", "x2 - x1", "N/m", "x2 - x1"),
    Term("libw_dv", "v2 - v1", "N s/m", "v2 - v1"),
    Term("libw_sgn", "sgn v2", "N", "v2"),
    Term("libw_vv", "v2|v2|", "N s^2/m^2", "v2"),
    Term("libw_volt", "V", "N/V", "V"),
    Term("libw_dvolt", "dV/dt", "N s/V", "V"),
)


@dataclass
class Trajectory:
    """What the library reads along one experiment's run, at the sample times."""

    t: NDArray[np.float64]
    x1: NDArray[np.float64]
    v1: NDArray[np.float64]
    x2: NDArray[np.float64]
    v2: NDArray[np.float64]
    ff: NDArray[np.float64]
    volt: NDArray[np.float64]
    dvolt: NDArray[np.float64]
    vs: float  #: the Stribeck velocity the smoothed sign uses [m/s]


def library_columns(tr: Trajectory, terms: Sequence[Term], wavelength: float) -> NDArray[np.float64]:
    """Each term's function along the trajectory (samples x terms), computed by the engine's own
    library force with that term's coefficient at 1 (rust/src/physics/library_columns.rs: sgn
    smoothed as tanh(v/v_s); the periodic terms at `wavelength` [m])."""
    from ...core import engine

    def f64(a: NDArray[np.float64]) -> NDArray[np.float64]:
        return np.ascontiguousarray(a, dtype=np.float64)

    return engine.library_columns(f64(tr.x1), f64(tr.v1), f64(tr.x2), f64(tr.v2), f64(tr.volt), f64(tr.dvolt),
                                  f64(tr.ff), f64(tr.t), float(tr.vs), float(wavelength), [t.param for t in terms])


#: each periodic term's partner in quadrature (the same kind of force a quarter period on)
QUADRATURE = {"lib_sin": "lib_cos", "lib_cos": "lib_sin", "lib_ff_sin": "lib_ff_cos", "lib_ff_cos": "lib_ff_sin"}
