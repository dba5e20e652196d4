"""The sampled external force (an input on a body beside the voltage) and the library force
effect: each against an independent statement of the same physics — a constant force is the
load force, the library's linear term is the ground spring, the budgets close with either on,
the knot derivatives are the central differences of runs, an adaptive run lands on the knots."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

import idm_rs
from idm_rs import Effects, ExternalForce

P = idm_rs.Params()
DT = 2e-8
W = idm_rs.Sawtooth(amplitude=80.0, frequency=200.0, cycles=2, rise=0.5e-3, direction="forward")
T_END = W.duration


def run(params=P, effects=None, force=None, energy=False, sensitivities=None, method="rk4", dt=DT, save_every=50):
    return idm_rs.simulate(params, W, T_END, dt if method == "rk4" else None, model="lps", save_every=save_every,
                           piezo_hysteresis=False, effects=effects, energy=energy, external_force=force,
                           sensitivities=sensitivities, method=method)


def test_a_constant_force_on_the_main_body_is_the_load_force():
    f = -0.08  # N, against the forward motion
    loaded = run(params=replace(P, load_force=f))
    pushed = run(force=ExternalForce([0.0, T_END], [f, f], body="main"))
    np.testing.assert_array_equal(pushed.main_body, loaded.main_body)
    # and it acts: the loaded device steps less far
    assert run().main_body[-1] - loaded.main_body[-1] > 1e-8


def test_a_force_on_the_weight_moves_the_weight_and_the_budgets_close():
    t = np.linspace(0.0, T_END, 21)
    force = ExternalForce(t, 0.3 * np.sin(2 * np.pi * t / T_END), body="weight")
    r = run(force=force, energy=True)
    base = run(energy=True)
    assert np.max(np.abs(r.nodes[:, -1] - base.nodes[:, -1])) > 1e-8
    # the external work and impulse include the sampled force: the budgets still close
    assert r.energy.relative_residual < 1e-9
    assert np.max(np.abs(r.energy.momentum_residual)) < 1e-9 * np.max(np.abs(r.energy.friction_impulse))


def test_the_library_force_runs_and_its_linear_term_is_the_ground_spring():
    k = 4e4
    spring = run(effects=Effects(k_ground=k))
    library = run(effects=Effects(lib_x1=-k))
    np.testing.assert_allclose(library.main_body, spring.main_body, rtol=0, atol=1e-15)
    # quadratic drag and position-periodic friction close the energy budget (the library's
    # forces are counted as external work)
    for e in (Effects(lib_vv=-30.0), Effects(lib_ff_sin=0.1, lib_wavelength=5e-6), Effects(libw_vv=-5.0)):
        r = run(effects=e, energy=True)
        assert np.max(np.abs(r.main_body - run().main_body)) > 1e-10, e
        assert r.energy.relative_residual < 1e-9, e


def test_knot_derivatives_are_central_differences_of_runs():
    t = np.linspace(0.0, T_END, 11)  # knots every 1 ms: multiples of dt
    f0 = 0.05 * np.cos(2 * np.pi * t / T_END)
    force = ExternalForce(t, f0)
    r = run(force=force, sensitivities=force.knot_names())
    assert r.sensitivities.shape == (r.t.size, t.size)
    for k in (2, 5, 9):
        h = 1e-6  # N: small against the force (50 mN), the run stays on its branches
        up = f0.copy()
        up[k] += h
        dn = f0.copy()
        dn[k] -= h
        fd = (run(force=ExternalForce(t, up)).reading - run(force=ExternalForce(t, dn)).reading) / (2 * h)
        exact = r.sensitivity(f"f_ext[{k}]")
        assert np.max(np.abs(exact)) > 1e-9  # the force at a knot moves the body
        np.testing.assert_allclose(exact, fd, rtol=0, atol=2e-4 * np.max(np.abs(fd)))
        # nothing before the knot's own piece starts
        assert np.all(exact[r.t < t[k - 1] - 1e-12] == 0.0)


def test_an_adaptive_run_lands_on_the_knots_and_agrees_with_rk4():
    t = np.array([0.0, 1.234e-3, 3.0e-3, T_END])  # a knot off any step grid
    force = ExternalForce(t, [0.0, 0.1, -0.05, 0.0])
    a = run(force=force, method="dopri5", save_every=1)
    assert np.min(np.abs(a.t - 1.234e-3)) < 1e-15
    b = run(force=ExternalForce([0.0, 1.2e-3, 3.0e-3, T_END], [0.0, 0.1, -0.05, 0.0]))
    assert abs(a.final_position - b.final_position) > 1e-12  # the knot's place matters


def test_bad_external_forces_are_refused_by_name():
    with pytest.raises(ValueError, match="external force's sample"):
        run(force=ExternalForce([0.0, 1.00001e-3, T_END], [0.0, 0.1, 0.0]))
    with pytest.raises(ValueError, match="f_ext"):
        run(force=ExternalForce([0.0, T_END], [0.0, 0.1]), sensitivities=["f_ext[2]"])
    with pytest.raises(ValueError, match="no external force"):
        run(sensitivities=["f_ext[0]"])
    with pytest.raises(ValueError, match="'main'"):
        ExternalForce([0.0, 1.0], [0.0, 1.0], body="base")
    with pytest.raises(ValueError, match="two samples"):
        ExternalForce([0.0], [1.0])
    with pytest.raises(ValueError, match="not finite"):
        run(force=ExternalForce([0.0, T_END], [0.0, np.nan]))
    with pytest.raises(TypeError, match="ExternalForce"):
        run(force=([0.0, T_END], [0.0, 1.0]))
