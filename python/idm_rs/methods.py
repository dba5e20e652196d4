"""Integration methods by name, and what ``method="auto"`` means.

``"rk4"`` is the fixed-step reference. ``"dopri5"`` (explicit Dormand-Prince 5(4)) and
``"rodas4"`` (linearly implicit Rosenbrock, order 4(3), L-stable, with the model's analytic
Jacobian) choose their own steps from ``rtol``/``atol`` and need no ``dt``.

``"auto"`` is the fastest adaptive setting that kept every point within 1 nm of RK4 at
dt = 1e-8 s where it was measured (``benches/bench_sweep.py`` and ``benches/bench_auto_corners.py``,
recorded in ``benches/RESULTS.md``): the 16 x 16 grid of mass ratio 0.25-2 x voltage 40-120 V
(paper case, 10 ms) for the LPS and the DPS with n = 4, and 12 x 12 grids in each of its four
corners (light or heavy weight, low or high voltage). There, Dormand-Prince at rtol = atol =
1e-6 missed 1 nm at one point, at 3e-7 at none. Rodas4 takes 2-10x fewer steps (most in the
high-voltage corners, where friction is stiff) but each step costs ~3.5x more (an LU
factorisation and six solves), so on these grids it is slower; "auto" will follow the
measurement when that changes.
"""

from __future__ import annotations

from typing import Literal

MethodName = Literal["rk4", "dopri5", "rodas4", "auto"]

#: every method name the engine and the Python API accept
METHODS: tuple[str, ...] = ("rk4", "dopri5", "rodas4", "auto")
#: the methods that choose their own step
ADAPTIVE: tuple[str, ...] = ("dopri5", "rodas4")

#: what "auto" resolves to: (method, rtol, atol), from the measurement described above
AUTO: tuple[str, float, float] = ("dopri5", 3e-7, 3e-7)


def check(method: object) -> str:
    """The method's name, or a ValueError naming the accepted ones."""
    if method not in METHODS:
        raise ValueError(f"parameter 'method' must be one of {', '.join(map(repr, METHODS))}; got {method!r}")
    return str(method)


def resolve(method: str, rtol: float, atol: float) -> tuple[str, float, float]:
    """(engine method, rtol, atol) for ``method``: "auto" becomes :data:`AUTO`."""
    check(method)
    if method == "auto":
        return AUTO
    return method, float(rtol), float(atol)
