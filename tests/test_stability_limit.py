"""The up-front RK4 step limit holds for every structure: the fine FEM bar's fastest modes are
held by its stiffness-proportional Rayleigh damping (|λ| ≈ β ω² on the negative real axis), not
by its undamped frequency. A step above the limit is refused before any work, naming the mode and
a step that fits the input; a step at the limit runs. Before, 200 elements at dt = 1e-8 s passed
the check (undamped limit 4.34e-8 s), then diverged with the friction blamed and a step to try
(5e-9 s) that diverged too."""

from __future__ import annotations

import math
import re

import numpy as np
import pytest

import idm_rs
from idm_rs.core import engine

P = idm_rs.Params()
#: a fast edge that excites every mode of the bar, then a fall: 10 µs in all
EDGE = idm_rs.Triangle(amplitude=80.0, rise=5e-6, fall=5e-6)
#: a step the friction state takes on this input whatever the bar (it diverges at 1e-6 s)
FRICTION_SAFE_DT = 1e-7


def _limit(n: int) -> float:
    return engine.rk4_step_limit(P._given(), engine.RunConfig(model="dps", n_elements=n))


def _fitted(limit: float) -> float:
    """The largest step not above ``limit`` that puts 5 µs and 10 µs on the step grid."""
    return EDGE.duration / (2 * math.ceil(EDGE.duration / 2 / limit))


@pytest.mark.parametrize("n", [1, 2, 3, 5, 8, 13, 20, 40, 70, 100, 140, 200])
def test_a_step_at_the_limit_runs_and_one_above_is_refused_up_front(n):
    limit = _limit(n)
    # a coarse bar is held by the friction state first (steps of about 5e-7 s here): the
    # structure's limit is run where it binds, from about 40 elements
    dt = _fitted(min(limit, FRICTION_SAFE_DT))
    r = idm_rs.simulate(P, EDGE, EDGE.duration, dt=dt, model="dps", n_elements=n, save_every=10**6)
    assert np.isfinite(r.final_position) and np.all(np.isfinite(r.nodes))
    above = 1.2 * limit
    wave = idm_rs.Triangle(amplitude=80.0, rise=10 * above, fall=10 * above)  # breakpoints on its grid
    with pytest.raises(ValueError, match="unstable for the structure's fastest mode") as err:
        idm_rs.simulate(P, wave, wave.duration, dt=above, model="dps", n_elements=n)
    said = float(re.search(r"use dt <= ([0-9.eE+-]+) s", str(err.value)).group(1))
    assert said == pytest.approx(limit, rel=1e-3)


def test_the_fine_bar_of_the_report_is_refused_and_its_suggested_step_runs():
    with pytest.raises(ValueError, match="overdamped mode") as err:
        idm_rs.simulate(P, EDGE, EDGE.duration, dt=1e-8, model="dps", n_elements=200)
    fits = float(re.search(r"dt = ([0-9.eE+-]+) s fits this input", str(err.value)).group(1))
    assert 1.0e-9 <= fits <= _limit(200) < 1.6e-9  # measured: only 1.25e-9 s of 5e-9 .. 1.25e-9 ran
    r = idm_rs.simulate(P, EDGE, EDGE.duration, dt=fits, model="dps", n_elements=200, save_every=10**6)
    assert np.isfinite(r.final_position)


def test_the_limit_is_rk4s_own_reach_on_the_damped_modes():
    """The limit is RK4's own, not a margin invented to pass: on the damped bar's eigenvalues,
    assembled here independently of the engine, |R(hλ)| <= 1 at 0.99x the true reach (the
    check's limit without its margin 2.5 / 2√2) and > 1 at 1.05x."""
    n = 100
    lam = _eigenvalues(n)
    limit = _limit(n) / (2.5 / (2 * math.sqrt(2)))
    for h, stable in ((0.99 * limit, True), (1.05 * limit, False)):
        z = h * lam
        growth = np.abs(1 + z + z**2 / 2 + z**3 / 6 + z**4 / 24).max()
        assert bool(growth <= 1 + 1e-9) is stable, (h, growth)


def _eigenvalues(n: int) -> np.ndarray:
    """The damped bar's eigenvalues from its matrices, assembled here independently of the engine
    (consistent mass, C = α Mp + β Kp as docs/MODEL.md says)."""
    p = P.to_dict(resolved=True)
    le = p["pe_length"] / n
    me, ke = p["pe_density"] * p["pe_area"] * le / 6, p["pe_youngs"] * p["pe_area"] / le
    mp, kp = np.zeros((n + 1, n + 1)), np.zeros((n + 1, n + 1))
    for e in range(n):
        mp[e:e + 2, e:e + 2] += me * np.array([[2.0, 1.0], [1.0, 2.0]])
        kp[e:e + 2, e:e + 2] += ke * np.array([[1.0, -1.0], [-1.0, 1.0]])
    m = mp.copy()
    m[0, 0] += p["m1"]
    m[n, n] += p["m2"]
    c = p["rayleigh_alpha"] * mp + p["rayleigh_beta"] * kp
    mi = np.linalg.inv(m)
    a = np.block([[np.zeros((n + 1, n + 1)), np.eye(n + 1)], [-mi @ kp, -mi @ c]])
    return np.linalg.eigvals(a)
