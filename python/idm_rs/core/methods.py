"""Integration methods by name, and what ``method="auto"`` means.

``"rk4"`` is the fixed-step reference. ``"dopri5"`` (explicit Dormand-Prince 5(4)) and
``"rodas4"`` (linearly implicit Rosenbrock, order 4(3), L-stable, with the model's analytic
Jacobian) choose their own steps from ``rtol``/``atol`` and need no ``dt``.

``"auto"`` runs each point with Dormand-Prince at rtol = atol = 3e-7, the fastest explicit
setting that kept every point within 1 nm of RK4 at dt = 1e-8 s where it was measured
(``benches/bench_sweep.py`` and ``benches/bench_auto_corners.py``, recorded in
``benches/RESULTS.md``: the 16 x 16 grid of mass ratio 0.25-2 x voltage 40-120 V, paper case,
10 ms, LPS and DPS n = 4, and 12 x 12 grids in each of its corners), and changes a point to
Rodas4 (rtol = atol = 1e-5, the loosest that kept the same grids within 1 nm) where that pays,
as LSODA changes between its methods: when Dormand-Prince's steps are held at its stability
limit (Hairer's test: h|lambda| at the limit for 256 accepted steps in a row), and in any case
every 1,024 accepted explicit steps (a probe: steps that resolve a lightly damped ringing are
held by accuracy, which the test cannot see), one Rodas4 step 20 times as long is tried, then
8 Rodas4 steps whose mean must be three times the cost ratio of the two methods' steps times
the explicit step (a Rodas4 step costs ~3.9 Dormand-Prince steps on the vector lanes for the
LPS, ~6 for the DPS with 4 elements). Passed, the point stays on Rodas4; failed, it goes back
to Dormand-Prince and tries again only after twice as many steps. A point on Rodas4 runs 8
Dormand-Prince steps every 32 implicit steps (64, then 128 while it stays) and goes back when
they have become the cheaper (their mean step times the cost ratio reaches Rodas4's): a stiff
phase ends when a sliding phase does. Each point
decides from its own run only, so its result never depends on its neighbours, the thread
count or the lane width. Rust: ``integrate/stiffness.rs``, ``integrate/switching.rs``.
"""

from __future__ import annotations

import math
from typing import Literal, Optional, cast

from . import engine

#: every method name the engine and the Python API accept, as the engine declares them
METHODS: tuple[str, ...] = tuple(str(d["name"]) for d in engine.method_declarations())
#: the methods that choose their own step
ADAPTIVE: tuple[str, ...] = tuple(str(d["name"]) for d in engine.method_declarations() if d["adaptive"])


def is_adaptive(method: str) -> bool:
    """Whether `method` chooses its own steps (rtol, atol) rather than taking a fixed `dt`: what
    every "does this run take dt?" question asks, so a new fixed-step method needs no edit
    where runs are prepared."""
    return method in ADAPTIVE


#: the type of a method name: spelled out for the type checker, held equal to METHODS by
#: tests/test_declarations.py
MethodName = Literal["rk4", "dopri5", "rodas4", "auto"]

#: what "auto" resolves to: (engine method, rtol, atol) of its explicit part, from the measurement
#: described above (the implicit part's tolerances are 10/3 of these)
AUTO: tuple[str, float, float] = ("auto", 3e-7, 3e-7)


def check(method: object) -> str:
    """The method's name, or a ValueError naming the accepted ones."""
    if method not in METHODS:
        raise ValueError(f"parameter 'method' must be one of {', '.join(map(repr, METHODS))}; got {method!r}")
    return str(method)


#: the adaptive methods' tolerances when none are given (dopri5, rodas4)
DEFAULT_TOLERANCE: float = 1e-7


def resolve(method: str, rtol: Optional[float] = None,
            atol: Optional[float] = None) -> tuple[MethodName, float, float]:
    """(engine method, rtol, atol) for ``method``. A tolerance left out (None) is the method's
    own: :data:`AUTO`'s for "auto" (the setting measured to keep 1 nm), :data:`DEFAULT_TOLERANCE`
    for the others. A tolerance given is honoured, by "auto" too (its implicit part then runs at
    10/3 of it); the 1 nm measurement holds for AUTO's only."""
    check(method)
    for name, value in (("rtol", rtol), ("atol", atol)):
        if value is not None and (isinstance(value, bool) or not float(value) > 0 or not math.isfinite(float(value))):
            raise ValueError(f"parameter '{name}' must be a positive number, got {value!r}")
    default = AUTO[1] if method == "auto" else DEFAULT_TOLERANCE
    name = cast(MethodName, method)  # check() accepted it
    return name, float(default if rtol is None else rtol), float(default if atol is None else atol)
