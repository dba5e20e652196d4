"""Parameter sensitivities from the engine (``simulate(..., sensitivities=[...])`` and the batch).

The claims: ``result.sensitivity(name)`` is d reading / d name at every saved time, the exact
derivative of the discrete run (forward-mode dual numbers through the same right-hand side and
integrator), so it matches central differences of the plain engine to their own accuracy; a
batch point's sensitivities equal those of ``simulate()`` for the same point; names that cannot
be differentiated are refused with the reason. The Rust tests (``sensitivity.rs``) check every
parameter, effect and structure against differences; these check the Python path.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

import idm_rs
from idm_rs import batch
from idm_rs.params import PARAM_INFO

WAVE = idm_rs.Triangle(80.0, 0.5e-3, 9.5e-3)
RUN = dict(t_end=1e-3, dt=1e-8, model="lps", save_every=2000)


def _readings(params: idm_rs.Params, effects: idm_rs.Effects | None = None, **kw) -> np.ndarray:
    return idm_rs.simulate(params, WAVE, effects=effects, **{**RUN, **kw}).reading


def _difference(name: str, h: float, params: idm_rs.Params, effects: idm_rs.Effects) -> np.ndarray:
    """Central difference of the readings in a Table 1 or effect parameter."""
    def at(v: float) -> np.ndarray:
        if name in PARAM_INFO:
            return _readings(params.replace(**{name: v}), effects)
        return _readings(params, dataclasses.replace(effects, **{name: v}))
    v = getattr(params, name, None)
    v = getattr(effects, name) if v is None else v
    return (at(v + h) - at(v - h)) / (2 * h)


def test_sensitivities_match_central_differences_of_the_engine():
    p = idm_rs.Params(normal_force=6.9)
    e = idm_rs.Effects(k_ground=2e3)
    names = ["mu_k", "m2", "k_ground", "d33"]
    r = idm_rs.simulate(p, WAVE, effects=e, sensitivities=names, **RUN)
    assert r.sensitivity_names == tuple(names)
    assert r.sensitivities.shape == (r.t.size, len(names))
    assert r.final_state_sensitivities.shape == (r.final_state.size, len(names))
    for name, h in [("mu_k", 5e-7), ("m2", 3e-7), ("k_ground", 2e-3), ("d33", 1.24e-13)]:
        d, fd = r.sensitivity(name), _difference(name, h, p, e)
        scale = np.abs(fd).max()
        assert scale > 0
        # the differences carry the run's rounding noise; far below any missing term
        assert np.abs(d - fd).max() < 1e-4 * scale, name
    # the last saved reading is the final state's x1: its derivative is the final state's
    np.testing.assert_allclose(r.final_state_sensitivities[0], r.sensitivities[-1], rtol=0, atol=0)


def test_initial_state_sensitivity_of_the_position_is_one_at_the_start():
    r = idm_rs.simulate(idm_rs.Params(), WAVE, sensitivities=["q0", "v0"], **RUN)
    assert r.sensitivity("q0")[0] == 1.0 and r.sensitivity("v0")[0] == 0.0
    # a shifted start moves the whole record by (nearly) the shift while the body sticks
    assert abs(r.sensitivity("q0")[1] - 1.0) < 0.1


def test_the_default_normal_force_follows_the_masses():
    derived = idm_rs.simulate(idm_rs.Params(), WAVE, sensitivities=["m2"], **RUN).sensitivity("m2")
    fixed = idm_rs.simulate(idm_rs.Params(normal_force=idm_rs.Params().effective_normal_force), WAVE,
                            sensitivities=["m2"], **RUN).sensitivity("m2")
    fd = _difference("m2", 3e-7, idm_rs.Params(), idm_rs.Effects())
    scale = np.abs(fd).max()
    assert np.abs(derived - fd).max() < 1e-4 * scale
    assert np.abs(fixed - derived).max() > 1e-3 * scale  # the normal force's share is not small
    with pytest.raises(ValueError, match="derived from the masses"):
        idm_rs.simulate(idm_rs.Params(), WAVE, sensitivities=["normal_force"], **RUN)


def test_an_adaptive_run_has_its_sensitivities_near_rk4s():
    rk4 = idm_rs.simulate(idm_rs.Params(), WAVE, sensitivities=["mu_k"], t_end=0.6e-3, dt=1e-9, model="lps",
                          save_every=600_000)
    dp = idm_rs.simulate(idm_rs.Params(), WAVE, sensitivities=["mu_k"], t_end=0.6e-3, model="lps",
                         method="dopri5", rtol=1e-9, atol=1e-9)
    assert abs(dp.sensitivity("mu_k")[-1] / rk4.sensitivity("mu_k")[-1] - 1) < 1e-3


def test_bad_names_are_refused_with_the_reason():
    with pytest.raises(ValueError, match="unknown sensitivity 'wind'.*mu_k"):
        idm_rs.simulate(idm_rs.Params(), WAVE, sensitivities=["wind"], **RUN)
    with pytest.raises(ValueError, match="'tau_amp': its effect is off"):
        idm_rs.simulate(idm_rs.Params(), WAVE, sensitivities=["tau_amp"], **RUN)
    with pytest.raises(TypeError, match="names"):
        idm_rs.simulate(idm_rs.Params(), WAVE, sensitivities=[3], **RUN)
    r = idm_rs.simulate(idm_rs.Params(), WAVE, sensitivities="mu_k", **RUN)  # one name
    with pytest.raises(ValueError, match="no sensitivity 'mu_s'.*mu_k"):
        r.sensitivity("mu_s")
    with pytest.raises(ValueError, match="no sensitivity"):
        idm_rs.simulate(idm_rs.Params(), WAVE, **RUN).sensitivity("mu_k")


def test_batch_points_have_the_sensitivities_of_simulate():
    points = [batch.Point(idm_rs.Params(m2=m2), waveform=WAVE) for m2 in (0.3, 0.45)]
    names = ["mu_k", "m1", "fh"]
    out = batch.run(points, batch.Structure("lps"), t_end=1e-3, dt=1e-8, record_every=2000,
                    sensitivities=names, threads=2)
    assert out["sensitivity_names"] == names
    s = out["sensitivities"]
    assert s.shape == (2, 3, out["traces"][0].size)
    for i, pt in enumerate(points):
        r = idm_rs.simulate(pt.params, WAVE, sensitivities=names, **RUN)
        np.testing.assert_array_equal(s[i].T, r.sensitivities)
    with pytest.raises(ValueError, match="record_every"):
        batch.run(points, batch.Structure("lps"), t_end=1e-3, dt=1e-8, sensitivities=names)
