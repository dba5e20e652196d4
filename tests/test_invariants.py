"""Physical invariants of the IDM model (MODEL.md, "Invariants"), checked as properties over
physical parameter ranges with hypothesis (profiles and strategies in conftest.py)."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, note
from hypothesis import strategies as st

import idm_rs
from conftest import (
    asperity_rate,
    physical_params,
    presliding_bound,
    rayleigh_alphas,
    short_runs,
    triangles,
)

# Saved per-time arrays of a SimulationResult
STATE_ARRAYS = ("nodes", "velocities", "friction", "fh", "g", "h", "piezo_force", "reading")


# --------------------------------------------------------------------------------------------
# energy and momentum
# --------------------------------------------------------------------------------------------
@pytest.mark.parametrize("model", ["lps", "dps"])
@given(run=st.data())
def test_energy_balance_closes(model, run):
    """1/2 v'Mv + 1/2 q'Kq = ∫Fp(v1 - v_w)dt - ∫Ff v1 dt - ∫v'Cv dt, to 1e-10 of the largest flow."""
    r = run.draw(short_runs(model=model))
    res = r.simulate(energy=True, save_every=50)
    e = res.energy
    note(f"relative residual {e.relative_residual:.3e}")
    # the run must actually move energy around for the check to mean anything
    assert np.max(np.abs(e.input_work)) > 0
    assert np.max(e.kinetic + e.strain) > 0
    assert e.relative_residual < 1e-10
    # Rayleigh damping only dissipates: its work never decreases
    assert np.all(np.diff(e.damping_work) >= -1e-18)


@pytest.mark.parametrize("model", ["lps", "dps"])
@given(run=st.data())
def test_momentum_balance_closes(model, run):
    """1'M v(T) + ∫Ff dt + αc ∫1'Mp v dt = 0 (no external force without effects)."""
    r = run.draw(short_runs(model=model, params=physical_params(rayleigh_alpha=rayleigh_alphas)))
    res = r.simulate(energy=True, save_every=50)
    e = res.energy
    scale = max(np.max(np.abs(e.momentum)), np.max(np.abs(e.friction_impulse)))
    assert scale > 0
    rel = np.max(np.abs(e.momentum_residual)) / scale
    note(f"relative momentum residual {rel:.3e}")
    assert rel < 1e-10
    if model == "lps":
        # the LPS has no PE mass, so no mass-proportional impulse
        assert np.all(e.rayleigh_impulse == 0.0)


# --------------------------------------------------------------------------------------------
# friction bounds
# --------------------------------------------------------------------------------------------
@given(
    run=short_runs(
        params=physical_params(
            # vary a/(b+c) from 2.5 to 6.7 N so that both branches of min(Fs, a/(b+c)) bind
            fric_gamma=st.floats(0.1e10, 0.6e10, allow_nan=False),
        )
    )
)
def test_presliding_force_stays_within_bound(run):
    """|Fh| <= min(Fs, a/(b+c)) at every step (save_every=1), from Fh(0) = 0."""
    res = run.simulate(save_every=1)
    bound = presliding_bound(run.params)
    peak = np.max(np.abs(res.fh))
    note(f"max|Fh| / bound - 1 = {peak / bound - 1:.3e}")
    assert res.fh.size == round(run.t_end / res.dt) + 1
    assert peak > 0.1 * bound  # the friction is actually loaded
    assert peak <= bound * (1 + 1e-9)


@given(run=short_runs())
def test_friction_force_bound(run):
    """|Ff| <= min(Fs, a/(b+c)) + σ1|dg/dt| + σ2|v|, with dg/dt recomputed from the saved state;
    and Ff is exactly Fh + σ1 dg/dt + σ2 v (eq. 9), so the bound is not vacuous."""
    res = run.simulate(save_every=10)
    p = run.params
    v, fh, ff = res.main_body_velocity, res.fh, res.friction
    gdot = asperity_rate(p, v, fh)
    model_ff = fh + p.sigma1 * gdot + p.sigma2 * v
    np.testing.assert_allclose(ff, model_ff, rtol=1e-12, atol=1e-12)
    bound = presliding_bound(p) + p.sigma1 * np.abs(gdot) + p.sigma2 * np.abs(v)
    assert np.all(np.abs(ff) <= bound * (1 + 1e-9))
    # the friction force is bounded and sizeable in a run that moves
    assert np.max(np.abs(ff)) > 0.1 * presliding_bound(p)


# --------------------------------------------------------------------------------------------
# exact identities
# --------------------------------------------------------------------------------------------
@given(
    run=short_runs(waveform=st.just(idm_rs.Triangle(amplitude=0.0, rise=0.5e-3, fall=0.5e-3))),
)
def test_rest_stays_exactly_at_rest(run):
    """V ≡ 0 from rest: every state, force and budget stays exactly 0.0."""
    res = run.simulate(save_every=7, energy=True)
    assert res.t.size > 2
    for name in STATE_ARRAYS + ("voltage", "final_state"):
        arr = getattr(res, name)
        assert np.all(arr == 0.0), f"{name} left rest: max |{name}| = {np.max(np.abs(arr))}"
    e = res.energy
    for name in ("kinetic", "strain", "input_work", "friction_work", "damping_work", "momentum",
                 "friction_impulse", "rayleigh_impulse"):
        arr = getattr(e, name)
        assert np.all(arr == 0.0), f"{name} is not 0: max {np.max(np.abs(arr))}"
    assert res.final_position == 0.0


@given(
    p=physical_params(pe_density=0.0, rayleigh_alpha=rayleigh_alphas),
    w=triangles(),
    hyst=st.booleans(),
)
def test_lps_equals_dps_one_massless_element(p, w, hyst):
    """With ρp = 0 and one element the DPS is the LPS (αc Mp vanishes): identical trajectories."""
    kw = dict(save_every=20, piezo_hysteresis=hyst, energy=True)
    lps = idm_rs.simulate(p, w, 2e-3, 1e-8, model="lps", **kw)
    dps = idm_rs.simulate(p, w, 2e-3, 1e-8, model="dps", n_elements=1, **kw)
    assert lps.nodes.shape == dps.nodes.shape == (lps.t.size, 2)
    assert np.max(np.abs(lps.nodes - dps.nodes)) <= 1e-15
    assert np.max(np.abs(lps.velocities - dps.velocities)) <= 1e-12
    for name in ("fh", "g", "h", "friction"):
        np.testing.assert_allclose(getattr(lps, name), getattr(dps, name), rtol=1e-12, atol=1e-15, err_msg=name)
    assert np.all(dps.energy.rayleigh_impulse == 0.0)
    assert np.max(np.abs(lps.nodes)) > 1e-8  # the run is not trivial: the PE stroke is ~d33 V


@pytest.mark.parametrize("piezo_hysteresis", [False, True])
@given(run=short_runs())
def test_reversed_voltage_mirrors_motion(piezo_hysteresis, run):
    """V -> -V negates every displacement, velocity and force exactly: Leuven friction is odd
    (S(v) even, dg/dt and dFh/dt odd in (v, Fh)), the structure is linear, and the Bouc-Wen
    piezo law dh/dt = ap d33 V' - bp|V'|h - cp V'|h| is odd in (V', h) too. (What is NOT
    symmetric is a time-reversed waveform: fast-rise/slow-fall vs slow-rise/fast-fall.)"""
    forward = run.simulate(save_every=25, piezo_hysteresis=piezo_hysteresis)
    w = run.waveform
    mirrored = idm_rs.Triangle(amplitude=-w.amplitude, rise=w.rise, fall=w.fall, delay=w.delay)
    backward = idm_rs.simulate(
        run.params, mirrored, run.t_end, forward.dt, model=run.model, n_elements=run.n_elements,
        save_every=25, piezo_hysteresis=piezo_hysteresis,
    )
    assert np.max(np.abs(forward.nodes)) > 1e-8  # not a trivial run
    for name in STATE_ARRAYS + ("voltage",):
        a, b = getattr(forward, name), getattr(backward, name)
        assert np.array_equal(a, -b), f"{name}: max |a + b| = {np.max(np.abs(a + b))}"
    assert forward.final_position == -backward.final_position


@given(run=short_runs(max_elements=7), save_every=st.integers(1, 500))
def test_bookkeeping_does_not_perturb_the_trajectory(run, save_every):
    """The energy/momentum accounting (which takes the core's general, heap-allocated path) and
    the save interval must not change the physics: the trajectory is bitwise that of the plain
    run (the core's fixed-size fast path for up to 6 nodes)."""
    plain = run.simulate(save_every=save_every)
    accounted = idm_rs.simulate(
        run.params, run.waveform, run.t_end, plain.dt, model=run.model, n_elements=run.n_elements,
        save_every=save_every, piezo_hysteresis=run.piezo_hysteresis, energy=True,
    )
    assert np.array_equal(plain.final_state, accounted.final_state[: plain.final_state.size])
    for name in STATE_ARRAYS:
        assert np.array_equal(getattr(plain, name), getattr(accounted, name)), name
    # a different save interval samples the same trajectory
    every_step = idm_rs.simulate(
        run.params, run.waveform, run.t_end, plain.dt, model=run.model, n_elements=run.n_elements,
        save_every=1, piezo_hysteresis=run.piezo_hysteresis,
    )
    idx = np.searchsorted(every_step.t, plain.t)
    assert np.array_equal(every_step.t[idx], plain.t)
    assert np.array_equal(every_step.nodes[idx], plain.nodes)
