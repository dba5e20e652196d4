"""Unit physics of each catalogue effect (docs/RECORDINGS.md) through ``idm_rs.simulate``.

Short LPS runs (a 2-cycle 200 Hz sawtooth, 10 ms, dt 2e-8 s, no piezo hysteresis), each compared
with the same run without the effect, so every test fails if the effect is missing, has the
wrong sign, or leaks into what it must not touch."""

from __future__ import annotations

from typing import Optional

import numpy as np
import pytest

import idm_rs
from idm_rs import Effects

P = idm_rs.Params()
DT = 2e-8
PERIOD = 5e-3  # 200 Hz


def sawtooth(amplitude: float = 80.0, direction: str = "forward", delay: float = 0.0) -> idm_rs.Sawtooth:
    return idm_rs.Sawtooth(amplitude=amplitude, frequency=200.0, cycles=2, rise=0.5e-3, direction=direction,
                           delay=delay)


def run(effects: Optional[Effects] = None, waveform: Optional[idm_rs.Waveform] = None, *, t_end: Optional[float] = None,
        dt: float = DT, save_every: int = 50, energy: bool = False) -> idm_rs.SimulationResult:
    w = waveform if waveform is not None else sawtooth()
    return idm_rs.simulate(P, w, t_end if t_end is not None else w.duration, dt, model="lps", save_every=save_every,
                           piezo_hysteresis=False, effects=effects, energy=energy)


def cycle_steps(r: idm_rs.SimulationResult) -> np.ndarray:
    """x1 gained over each of the two cycles [m] (the sawtooths here start at t = 0)."""
    idx = [int(np.argmin(np.abs(r.t - k * PERIOD))) for k in range(3)]
    return np.diff(r.main_body[idx])


# --- incline --------------------------------------------------------------------------------------


@pytest.mark.parametrize("theta", [2e-3, -2e-3])
def test_incline_shifts_forward_and_backward_steps_in_opposite_directions(theta):
    """Gravity along a guide tilted by theta > 0 pushes the body backward: forward steps shrink and
    backward steps grow (in magnitude); theta < 0 does the opposite."""
    fwd0, bwd0 = cycle_steps(run()), cycle_steps(run(waveform=sawtooth(direction="backward")))
    fwd, bwd = cycle_steps(run(Effects(theta_rad=theta))), cycle_steps(
        run(Effects(theta_rad=theta), sawtooth(direction="backward")))
    assert np.all(fwd0 > 0) and np.all(bwd0 < 0)
    d_fwd, d_bwd = fwd - fwd0, bwd - bwd0
    # both shifts point down the slope: backward (negative) for theta > 0
    assert np.all(np.sign(d_fwd) == -np.sign(theta))
    assert np.all(np.sign(d_bwd) == -np.sign(theta))
    if theta > 0:
        assert np.all(fwd < fwd0) and np.all(np.abs(bwd) > np.abs(bwd0))
    else:
        assert np.all(fwd > fwd0) and np.all(np.abs(bwd) < np.abs(bwd0))
    # a visible effect, not rounding: at least 1 nm per cycle
    assert np.all(np.abs(d_fwd) > 1e-9) and np.all(np.abs(d_bwd) > 1e-9)


# --- spring_to_ground -------------------------------------------------------------------------------


def test_spring_to_ground_pulls_the_body_toward_zero():
    free = run()
    sprung = run(Effects(k_ground=2e4))
    assert free.final_position > 1e-6  # the body walked forward
    assert 0 < sprung.final_position < free.final_position - 1e-8
    assert np.max(np.abs(sprung.main_body)) < np.max(np.abs(free.main_body))


def test_spring_to_ground_with_a_huge_stiffness_holds_the_body():
    """k_ground = 1e10 N/m, far above the PE's kp ~ 2.8e7 N/m: x1 stays below 1 % of its free motion."""
    free = run()
    held = run(Effects(k_ground=1e10))
    assert np.max(np.abs(held.main_body)) < 0.01 * np.max(np.abs(free.main_body))
    # the weight still moves by about the PE stroke: the PE works against the ground, not the body
    assert np.max(np.abs(held.weight)) > 0.5 * P.d33 * 80.0


# --- amplifier_lowpass --------------------------------------------------------------------------------


def _onset(r: idm_rs.SimulationResult, threshold: float = 5e-9) -> float:
    """First saved time at which x1 exceeds `threshold` [m]."""
    above = r.main_body > threshold
    assert above.any()
    return float(r.t[np.argmax(above)])


def test_amplifier_lowpass_delays_the_motion_onset():
    """A first-order amplifier lags a ramp by at most tau (tau (1 - exp(-t/tau))): the body starts
    moving later, by between half a tau and one tau here."""
    w = sawtooth(delay=1e-3)
    tau = 2e-5
    nominal = run(waveform=w, save_every=5)
    lagged = run(Effects(tau_amp=tau), w, save_every=5)
    delay = _onset(lagged) - _onset(nominal)
    assert 0.5 * tau < delay < tau


def test_amplifier_lowpass_tends_to_the_nominal_as_tau_vanishes():
    w = sawtooth(delay=1e-3)
    nominal = run(waveform=w, dt=1e-8, save_every=100)
    # tau = 0 is the nominal model exactly (the state is not even integrated)
    off = run(Effects(tau_amp=0.0), w, dt=1e-8, save_every=100)
    np.testing.assert_array_equal(off.main_body, nominal.main_body)
    np.testing.assert_array_equal(off.reading, nominal.reading)
    # and the deviation falls in proportion to tau
    dev = {tau: np.max(np.abs(run(Effects(tau_amp=tau), w, dt=1e-8, save_every=100).main_body - nominal.main_body))
           for tau in (1e-6, 1e-7)}
    assert dev[1e-6] > 1e-9
    assert dev[1e-7] < 0.15 * dev[1e-6]
    assert dev[1e-7] < 3e-9


# --- piezo_creep ----------------------------------------------------------------------------------------


def _creep_exact(t: np.ndarray, t_v: list, v: list, kappa: float, tau: float) -> np.ndarray:
    """xc(t) of dxc/dt = (kappa d33 V(t) - xc)/tau from xc(0) = 0, V piecewise linear (fine exact steps)."""
    tt = np.linspace(0.0, float(t[-1]), 400_001)
    u = kappa * P.d33 * np.interp(tt, t_v, v)
    a = np.exp(-(tt[1] - tt[0]) / tau)
    xc = np.zeros_like(tt)
    for i in range(1, tt.size):
        um = 0.5 * (u[i] + u[i - 1])
        xc[i] = um + (xc[i - 1] - um) * a
    return np.interp(t, tt, xc)


def test_piezo_creep_adds_extension_with_time_constant_tau_creep():
    """Ramp to 80 V and hold: the PE extension x1 - x2 gains the creep xc, which relaxes to
    kappa d33 V with time constant tau_creep (the masses follow quasi-statically)."""
    t_v, v = [0.0, 1e-3, 1.5e-3], [0.0, 0.0, 80.0]
    wave = idm_rs.Sampled(t_v, v)
    kappa, tau = 0.05, 2e-3
    t_end = 10e-3
    nominal = run(waveform=wave, t_end=t_end)
    creep = run(Effects(kappa=kappa, tau_creep=tau), wave, t_end=t_end)
    extra = (creep.main_body - creep.weight) - (nominal.main_body - nominal.weight)
    full = kappa * P.d33 * 80.0
    late = creep.t > 3e-3  # after the step's slip
    np.testing.assert_allclose(extra[late], _creep_exact(creep.t, t_v, v, kappa, tau)[late], rtol=0, atol=0.03 * full)
    # the time constant: ~1 - 1/e of the final creep one tau after the hold begins, ~95 % after three
    at = np.interp([1.5e-3 + tau, 1.5e-3 + 3 * tau], creep.t, extra) / full
    assert 0.6 < at[0] < 0.7
    assert 0.93 < at[1] < 0.97
    # a wrong time constant would not match: half of tau gives a clearly different curve
    fast = _creep_exact(creep.t, t_v, v, kappa, tau / 2)
    assert np.max(np.abs(extra[late] - fast[late])) > 0.1 * full


# --- weight_friction ------------------------------------------------------------------------------------


def test_weight_friction_dissipates_energy_and_the_balance_closes():
    r = run(Effects(c_weight=2.0), energy=True)
    e = r.energy
    # drag -c v2 only ever takes energy out: its work falls monotonically and ends negative
    assert e.external_work[-1] < -1e-8
    assert np.all(np.diff(e.external_work) <= 1e-18)
    assert e.relative_residual < 1e-10
    # without the drag there is no external work at all
    assert np.all(run(energy=True).energy.external_work == 0.0)


# --- friction_asymmetry -----------------------------------------------------------------------------------


def test_friction_is_mirror_symmetric_without_asymmetry():
    fwd = run(waveform=sawtooth(80.0))
    mirrored = run(waveform=sawtooth(-80.0))
    np.testing.assert_allclose(mirrored.main_body, -fwd.main_body, rtol=0, atol=1e-15)


@pytest.mark.parametrize("eps", [0.05, -0.05])
def test_friction_asymmetry_makes_forward_steps_smaller_than_mirrored_backward_ones(eps):
    """Friction x (1 + eps sgn v1): eps > 0 brakes forward sliding more, so a forward step is
    smaller than the backward step of the mirrored drive (-V); eps < 0 the reverse."""
    eff = Effects(eps=eps)
    fwd = cycle_steps(run(eff, sawtooth(80.0)))
    bwd = cycle_steps(run(eff, sawtooth(-80.0)))
    assert np.all(fwd > 0) and np.all(bwd < 0)
    if eps > 0:
        assert np.all(fwd < np.abs(bwd) - 1e-9)
    else:
        assert np.all(fwd > np.abs(bwd) + 1e-9)


# --- sensor_lowpass -------------------------------------------------------------------------------------


def test_sensor_lowpass_changes_the_reading_not_the_motion():
    tau = 1e-5
    nominal = run(save_every=5)
    r = run(Effects(tau_sensor=tau), save_every=5)
    # the motion is bitwise the nominal one
    np.testing.assert_array_equal(r.main_body, nominal.main_body)
    np.testing.assert_array_equal(r.nodes, nominal.nodes)
    np.testing.assert_array_equal(r.friction, nominal.friction)
    # the reading lags x1
    lag = np.max(np.abs(r.reading - r.main_body))
    assert lag > 1e-8
    # ... exactly as a first-order filter of x1 (x1 linear between the saved points: exact step)
    x1, t = r.main_body, r.t
    y = np.zeros_like(x1)
    for i in range(1, t.size):
        h = t[i] - t[i - 1]
        s = (x1[i] - x1[i - 1]) / h
        y[i] = x1[i] - s * tau + (y[i - 1] - x1[i - 1] + s * tau) * np.exp(-h / tau)
    np.testing.assert_allclose(r.reading, y, rtol=0, atol=1e-4 * lag)


# --- thermal_drift --------------------------------------------------------------------------------------


def test_thermal_drift_adds_exactly_drift_rate_times_t_to_the_reading():
    rate = 3e-7
    nominal = run()
    r = run(Effects(drift_rate=rate))
    np.testing.assert_allclose(r.reading, nominal.main_body + rate * r.t, rtol=0, atol=1e-18)
    assert abs(r.reading[-1] - r.main_body[-1] - rate * r.t[-1]) < 1e-18 and rate * r.t[-1] > 1e-9
    for name in ("nodes", "velocities", "friction", "fh", "g", "piezo_force"):
        np.testing.assert_array_equal(getattr(r, name), getattr(nominal, name), err_msg=name)


# --- energy balance ---------------------------------------------------------------------------------------


FORCE_EFFECTS = {
    "incline": Effects(theta_rad=3e-3),
    "spring_to_ground": Effects(k_ground=5e4),
    "amplifier_lowpass": Effects(tau_amp=1e-5),
    "piezo_creep": Effects(kappa=0.05, tau_creep=2e-3),
    "weight_friction": Effects(c_weight=2.0),
    "friction_asymmetry": Effects(eps=0.05),
}


@pytest.mark.parametrize("name", list(FORCE_EFFECTS))
def test_energy_balance_closes_with_each_force_effect(name):
    """kinetic + strain = input - friction - damping + external work, to 1e-10 of the largest flow."""
    eff = FORCE_EFFECTS[name]
    r = run(eff, energy=True)
    nominal = run()
    assert np.max(np.abs(r.main_body - nominal.main_body)) > 1e-9  # the effect acts
    e = r.energy
    assert np.max(np.abs(e.input_work)) > 0
    assert e.relative_residual < 1e-10


def test_bench_fixed_forces_are_declared_effect_parameters_and_turn_with_the_rig():
    """Every name in BENCH_FIXED is an effect parameter of the engine's declarations whose
    domain is symmetric (the turned value is valid too), and `oriented` negates exactly those."""
    from idm_rs.core import engine
    from idm_rs.core.effects import BENCH_FIXED, oriented

    names = set(engine.effect_names())
    assert BENCH_FIXED and BENCH_FIXED <= names
    values = {n: 0.25 for n in names}
    turned = oriented(values, True)
    assert {n for n in names if turned[n] == -0.25} == BENCH_FIXED
    assert oriented(values, False) == values
    for n in BENCH_FIXED:
        idm_rs.Effects(**{n: -0.01})  # the turned value is accepted


#: catalogue effects that put no force on a body (the reading's lag and drift): the energy
#: budget has nothing of theirs to close
NO_FORCE = {"sensor_lowpass", "thermal_drift"}


def test_the_effect_lists_of_the_tests_cover_every_catalogue_effect():
    """A new effect fails here until the energy-balance test (FORCE_EFFECTS) and the drawn
    effects of the property tests (conftest.EFFECT_RANGES; creep is drawn as its pair) know it:
    these lists are kept by hand, so a gap is made loud."""
    from conftest import EFFECT_RANGES
    from idm_rs.core.declarations import EFFECTS
    from idm_rs.diagnosis.catalogue import LIBRARY_IDS

    term = [e for e in EFFECTS if e.kind == "term" and e.id not in LIBRARY_IDS]
    assert {e.id for e in term} - NO_FORCE == set(FORCE_EFFECTS)
    assert {p.name for e in term for p in e.params} == set(EFFECT_RANGES) | {"kappa", "tau_creep"}
