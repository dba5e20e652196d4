"""The friction test rig (one body on the Leuven element, driven through a spring or by a force)
through the Python API: the analytic limits of stick and steady sliding."""

import math

import numpy as np
import pytest

import idm_rs
from idm_rs.core.batch import Rig

RIG_PARAMS = idm_rs.Params(m1=0.5, normal_force=0.5 * 9.81)


def test_spring_slider_breaks_away_when_the_spring_reaches_static_friction():
    k, speed = 2e4, 1e-3
    ramp = idm_rs.Sampled([0.0, 1.0], [0.0, speed])  # far end of the spring [m]
    r = idm_rs.simulate(RIG_PARAMS, ramp, 0.2, dt=1e-7, model=Rig("position", stiffness=k),
                        piezo_hysteresis=False, save_every=1)
    p = RIG_PARAMS
    fs = p.mu_s * p.effective_normal_force
    slip = int(np.argmax(np.abs(r.main_body_velocity) > 0.1 * p.stribeck_velocity))
    assert slip > 0
    spring = k * (speed * r.t[slip] - r.main_body[slip])
    assert spring / fs == pytest.approx(1.0, rel=0.02)
    assert r.model == "rig" and r.nodes.shape[1] == 1


def test_steady_sliding_friction_is_the_stribeck_curve_plus_viscous():
    speed = 0.02
    ramp = idm_rs.Sampled([0.0, 1.0], [0.0, speed])
    r = idm_rs.simulate(RIG_PARAMS, ramp, 0.05, dt=2e-8, model=Rig("position", 1e5, 500.0),
                        piezo_hysteresis=False, save_every=10**6)
    p = RIG_PARAMS
    fn = p.effective_normal_force
    fc, fs = p.mu_k * fn, p.mu_s * fn
    expected = fc + (fs - fc) * math.exp(-((speed / p.stribeck_velocity) ** p.stribeck_exponent)) + p.sigma2 * speed
    assert r.main_body_velocity[-1] == pytest.approx(speed, rel=1e-6)
    assert r.friction[-1] == pytest.approx(expected, rel=1e-6)


def test_rig_refuses_piezo_physics_and_bad_drives_by_name():
    step = idm_rs.Sampled([0.0, 1e-3], [0.0, 1.0])
    with pytest.raises(ValueError, match="piezo_hysteresis"):
        idm_rs.simulate(RIG_PARAMS, step, 1e-3, dt=1e-7, model=Rig("force"))
    with pytest.raises(ValueError, match="'c_weight'"):
        idm_rs.simulate(RIG_PARAMS, step, 1e-3, dt=1e-7, model=Rig("force"), piezo_hysteresis=False,
                        effects=idm_rs.Effects(c_weight=1.0))
    with pytest.raises(ValueError, match="'rig_drive'"):
        idm_rs.simulate(RIG_PARAMS, step, 1e-3, dt=1e-7, model=Rig("torque"), piezo_hysteresis=False)  # type: ignore[arg-type]
    with pytest.raises(ValueError, match="'rig_stiffness'"):
        idm_rs.simulate(RIG_PARAMS, step, 1e-3, dt=1e-7, model=Rig("position", -1.0), piezo_hysteresis=False)
