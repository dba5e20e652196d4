"""Actuator characteristics: steady-state metrics of sawtooth trains (checked against the RK4
trajectory itself), the external load force (checked against Newton's law), the stall force and
the ``characterize`` figure set."""

from __future__ import annotations

import math

import numpy as np
import pytest

import idm_rs
from idm_rs.apps.actuator import STEADY_METRICS, characterize, plot_characteristics, stall_force, steady_state

P = idm_rs.Params()
#: moves forward (with this device a much faster edge, 0.1 ms at 1 kHz, moves it backward)
TRAIN = idm_rs.Sawtooth(amplitude=80.0, frequency=200.0, cycles=5, rise=0.5e-3)
DT = 2e-8


@pytest.fixture(scope="module")
def rk4_run() -> idm_rs.SimulationResult:
    return idm_rs.simulate(P, TRAIN, t_end=TRAIN.duration, dt=DT, model="lps", save_every=1)


def test_steady_metrics_equal_the_trajectory_at_the_cycle_boundaries(rk4_run):
    """Independent reference: the RK4 trajectory saved at every step, read at the boundaries."""
    skip = 1
    s = rk4_run.steady_state(skip_cycles=skip)
    t, x = rk4_run.t, rk4_run.main_body
    bounds = [np.argmin(np.abs(t - k * TRAIN.period)) for k in range(TRAIN.cycles + 1)]
    steps = np.diff(x[bounds])[skip:]
    cycles = [np.diff(x[a:b + 1]) for a, b in zip(bounds[skip:-1], bounds[skip + 1:])]
    fwd = np.array([d[d > 0].sum() for d in cycles])
    bwd = np.array([-d[d < 0].sum() for d in cycles])
    assert s.step_mean == pytest.approx(steps.mean(), rel=1e-12, abs=1e-18)
    assert s.step_std == pytest.approx(steps.std(ddof=1), rel=1e-9, abs=1e-18)
    assert s.mean_velocity == pytest.approx(steps.mean() * TRAIN.frequency, rel=1e-12)
    np.testing.assert_allclose(fwd - bwd, steps, rtol=1e-9)  # the travel adds up to the step
    assert s.direction == 1.0 and s.motion == "forward"
    assert s.backslip == pytest.approx(bwd.mean(), rel=1e-9)
    assert s.backslip_ratio == pytest.approx(bwd.sum() / fwd.sum(), rel=1e-9)
    assert s.step_mean > 0 and 0 < s.backslip_ratio < 1


def test_sweep_metrics_equal_steady_state_for_the_same_point():
    ds = idm_rs.sweep(P, TRAIN, {"voltage": [60.0, 80.0]}, t_end=TRAIN.duration, dt=DT, model="lps",
                      skip_cycles=1, progress=False)
    s = steady_state(P, TRAIN, model="lps", skip_cycles=1, method="rk4", dt=DT)
    for name in STEADY_METRICS:
        assert ds[name].values[1] == getattr(s, name), name
        assert ds[name].attrs["units"] == STEADY_METRICS[name][0]
    assert ds.attrs["skip_cycles"] == 1
    # more voltage, longer steps
    assert ds.step_mean.values[0] < ds.step_mean.values[1]


def test_backward_train_moves_backward():
    back = idm_rs.Sawtooth(amplitude=80.0, frequency=200.0, cycles=4, rise=0.5e-3, direction="backward")
    s = steady_state(P, back, model="lps", method="auto")
    assert s.direction == -1.0 and s.step_mean < 0 and s.mean_velocity < 0
    assert s.backslip > 0


def test_triangle_input_has_no_steady_metrics():
    ds = idm_rs.sweep(P, idm_rs.Triangle(), {"voltage": [80.0]}, t_end=1e-3, model="lps", method="auto",
                      progress=False)
    assert math.isnan(ds.mean_velocity.values[0]) and math.isnan(ds.direction.values[0])
    with pytest.raises(ValueError, match="Sawtooth"):
        steady_state(P, idm_rs.Triangle(), model="lps")


def test_skipping_every_cycle_is_refused_by_name():
    with pytest.raises(ValueError, match="skip_cycles"):
        steady_state(P, TRAIN, model="lps", skip_cycles=5)
    with pytest.raises(ValueError, match="skip_cycles"):
        idm_rs.sweep(P, TRAIN, {"voltage": [80.0]}, t_end=1e-3, model="lps", skip_cycles=-1, progress=False)


# --- the load force ------------------------------------------------------------------------------


def test_a_load_above_static_friction_accelerates_the_device_as_newton_says():
    """No drive (0 V): a constant force F > Fs on the main body slides the whole device; with
    Coulomb friction Fc and viscous sigma2, M x'' = F - Fc - sigma2 v (presliding settles fast)."""
    fn = P.effective_normal_force
    force = 2.0 * P.mu_s * fn
    p = P.replace(load_force=force)
    r = idm_rs.simulate(p, idm_rs.Triangle(amplitude=0.0), t_end=2e-3, dt=1e-8, model="lps", save_every=1000)
    m = P.m1 + P.m2
    a = (force - P.mu_k * fn) / m
    # x(t) with the viscous term: (a tau) (t - tau (1 - e^{-t/tau})), tau = M / sigma2 (>> 2 ms)
    tau = m / P.sigma2
    t = r.t[-1]
    expected = a * tau * (t - tau * (1 - math.exp(-t / tau)))
    assert r.final_position == pytest.approx(expected, rel=0.03)


def test_a_load_below_static_friction_only_strains_the_contact():
    p = P.replace(load_force=0.3 * P.mu_s * P.effective_normal_force)
    r = idm_rs.simulate(p, idm_rs.Triangle(amplitude=0.0), t_end=2e-3, dt=1e-8, model="lps")
    assert 0 < r.final_position < 1e-9  # presliding: Fh / a ~ 1e-10 m


def test_opposing_load_slows_the_drive_and_the_stall_force_brackets_zero_velocity():
    train = TRAIN
    st = stall_force(P, train, model="lps", skip_cycles=2, loads=7)
    fs = P.mu_s * P.effective_normal_force
    assert st.direction == 1.0
    assert 0 < st.force < 1.5 * fs
    assert np.all(np.diff(st.velocities[np.isfinite(st.velocities)]) < 0)  # monotone: more load, slower
    below = steady_state(P.replace(load_force=-(st.force - 5 * st.xtol)), train, model="lps", skip_cycles=2)
    above = steady_state(P.replace(load_force=-(st.force + 5 * st.xtol)), train, model="lps", skip_cycles=2)
    assert below.mean_velocity > 0 > above.mean_velocity


# --- characterize -------------------------------------------------------------------------------


def test_characterize_gives_the_standard_set_and_its_figures(tmp_path):
    ds = characterize(P, model="lps", frequencies=[100.0, 200.0, 500.0], voltages=(60.0, 100.0),
                      step_voltages=[40.0, 80.0, 120.0], frequency=200.0, voltage=80.0, rise=0.5e-3, cycles=4,
                      skip_cycles=1, loads=5, progress=False)
    assert ds.mean_velocity.dims == ("voltage", "frequency")
    assert ds.mean_velocity.attrs["units"] == "m/s"
    assert np.isfinite(ds.mean_velocity.values).all() and (ds.direction.values == 1).all()
    # the design point's velocity is the load curve's unloaded end (same runs, two routes)
    assert ds.load_velocity.values[0] > 0
    assert np.all(np.diff(ds.step_mean_vs_voltage.values) > 0)
    assert np.isfinite(float(ds.stall_force)) and ds.attrs["stall_force_N"] == float(ds.stall_force)
    assert ds.attrs["velocity_at_design_m_per_s"] == float(ds.load_velocity[0]) > 0
    paths = plot_characteristics(ds, tmp_path)
    assert [p.name for p in paths] == ["velocity_vs_frequency.png", "step_backslip_vs_voltage.png",
                                       "velocity_vs_load.png"]
    assert all(p.stat().st_size > 10_000 for p in paths)


def test_characterize_cli(tmp_path):
    from idm_rs.apps.cli import main

    rc = main(["characterize", "--out", str(tmp_path), "--model", "lps", "--frequencies", "200,500",
               "--voltages", "80", "--step-voltages", "60,100", "--frequency", "200", "--rise", "5e-4",
               "--cycles", "3", "--skip-cycles", "1", "--loads", "4", "--no-progress"])
    assert rc == 0
    assert (tmp_path / "characteristics.nc").exists() and (tmp_path / "velocity_vs_load.png").exists()


def test_the_readme_design_point_by_a_second_route():
    """README: the paper's device (DPS, n = 4) at 100 Hz and 80 V moves at 0.138 mm/s and stalls
    under 0.558 N. Second route, not through ``characterize``: ``simulate()`` the sawtooth train
    and read the steady step from x1 at the cycle boundaries (after two start-up cycles); under
    an opposing load of 0.558 N the step is gone (< 1 % of the unloaded one), under 0.5 N not."""
    saw = idm_rs.Sawtooth(80.0, 100.0, 6, rise=0.5e-3)
    bounds = saw.delay + np.arange(2, 7) * saw.period

    def velocity(load: float) -> float:
        r = idm_rs.simulate(P.replace(load_force=-load), saw, t_end=saw.duration, model="dps", method="auto",
                            save_every=1)
        return float(np.mean(np.diff(np.interp(bounds, r.t, r.main_body)))) * saw.frequency

    free = velocity(0.0)
    assert free == pytest.approx(0.138e-3, rel=5e-3)
    assert abs(velocity(0.558)) < 0.01 * free
    assert velocity(0.5) > 0.05 * free
