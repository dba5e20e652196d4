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
from idm_rs.core import batch
from idm_rs.core.params import PARAM_INFO

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


def test_sensitivities_travel_with_the_dataset_with_their_units():
    r = idm_rs.simulate(idm_rs.Params(), WAVE, sensitivities=["mu_k", "m2", "q0"], **RUN)
    ds = r.to_xarray()
    np.testing.assert_array_equal(ds["d_reading_d_m2"].values, r.sensitivity("m2"))
    assert ds["d_reading_d_mu_k"].attrs["units"] == "m"
    assert ds["d_reading_d_m2"].attrs["units"] == "m/(kg)"
    assert ds["d_reading_d_q0"].attrs["units"] == "m/(m)"


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


def test_a_case_simulator_predicts_with_sensitivities_as_its_fits_need():
    """The diagnosis's case model gives each experiment's readings with their derivatives
    (the building block of exact fit Jacobians); where RK4's fit step is beyond the friction
    state's stability limit (fast slips), it says so instead of returning chatter's derivatives."""
    from pathlib import Path

    from idm_rs.core.batch import Structure
    from idm_rs.diagnosis.case_model import CaseSimulator, ModelSpec
    from idm_rs.io.recording import load_case

    case = Path(__file__).resolve().parents[1].parent / "shared" / "recordings" / "dev" / "dev02"
    if not case.is_dir():
        pytest.skip(f"dev recordings not found at {case}")
    rec = load_case(case)
    nom = rec.nominal
    params = nom.params.to_dict(resolved=False)
    # a Stribeck peak: at mu_s = mu_k exactly (this case's nominal) the readings have a kink in
    # mu_k (one-sided differences disagree by 1e-3 of the scale), which differences cannot judge
    params["mu_s"] = 1.1 * params["mu_k"]
    spec = ModelSpec(Structure(nom.model, nom.n_elements, nom.piezo_hysteresis), params, {})
    sim = CaseSimulator(rec, threads=2)
    names = ["mu_k", "m2"]
    preds, sens, why = sim.predict_with_sensitivities([spec], names, cycles=1)
    plain = sim.predict([spec], cycles=1)
    for j in range(len(rec.experiments)):
        np.testing.assert_array_equal(preds[0][j], plain[0][j])
        assert sens[0][j].shape == (2, preds[0][j].size)
    # experiment 0 (40 V) slips slowly enough for the fit step: its derivatives match differences
    assert np.isfinite(sens[0][0]).all() and why[0][0] == ""
    for k, (name, h) in enumerate([("mu_k", 1e-6), ("m2", 1e-7)]):
        p = dict(spec.params)
        value = p[name] if p.get(name) is not None else getattr(idm_rs.Params(), name)
        up = ModelSpec(spec.structure, {**p, name: value + h}, {})
        down = ModelSpec(spec.structure, {**p, name: value - h}, {})
        fd = (sim.predict([up], cycles=1)[0][0] - sim.predict([down], cycles=1)[0][0]) / (2 * h)
        scale = np.abs(fd).max()
        assert np.abs(sens[0][0][k] - fd).max() < 1e-3 * scale, name
    # the nominal device's experiment 1 (60 V) slips at 8 mm/s: beyond the fit step's limit,
    # named with the step that works
    nominal = ModelSpec(spec.structure, nom.params.to_dict(resolved=False), {})
    _, sens_all, why_all = sim.predict_with_sensitivities([nominal], names)
    assert not np.isfinite(sens_all[0][1]).all()
    assert "stability limit of the friction state" in why_all[0][1]
