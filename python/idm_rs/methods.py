"""Integration methods by name, and what ``method="auto"`` means.

``"rk4"`` is the fixed-step reference. ``"dopri5"`` (explicit Dormand-Prince 5(4)) and
``"rodas4"`` (linearly implicit Rosenbrock, order 4(3), L-stable, with the model's analytic
Jacobian) choose their own steps from ``rtol``/``atol`` and need no ``dt``.

``"auto"`` is the fastest adaptive setting that kept every point within 1 nm of RK4 at
dt = 1e-8 s on the benchmark grids (``benches/bench_sweep.py --auto-check``: the 16 x 16 mass
ratio 0.25-2 x voltage 40-120 V grid for the LPS and the DPS with n = 4, plus the hard corners
of a 1,000 x 1,000 grid); the measurement is recorded in ``benches/RESULTS.md``.
"""

from __future__ import annotations

from typing import Literal

MethodName = Literal["rk4", "dopri5", "rodas4", "auto"]

#: every method name the engine and the Python API accept
METHODS: tuple[str, ...] = ("rk4", "dopri5", "rodas4", "auto")
#: the methods that choose their own step
ADAPTIVE: tuple[str, ...] = ("dopri5", "rodas4")

#: what "auto" resolves to: (method, rtol, atol), from the measurement described above
AUTO: tuple[str, float, float] = ("rodas4", 1e-4, 1e-4)


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
