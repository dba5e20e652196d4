"""IDM recordings whose drive is recorded sample by sample (``waveform: "sampled"``): the format,
the noise floor without a rest segment, and the diagnosis on such cases (a healthy device with a
mis-set coefficient is "none"; a spring to ground is named)."""

from __future__ import annotations

import json

import numpy as np
import pytest

import idm_rs
from idm_rs.diagnosis import text_report
from idm_rs.diagnosis.noise import estimate_noise
from idm_rs.io.recording import RecordingError
from idm_rs.io.synthetic import make_case

P = idm_rs.Params()


def _drive(rest: float = 0.002) -> idm_rs.Sampled:
    """Fast rises of varied size and curved slow falls: no sawtooth describes it."""
    t = np.arange(0, 0.024 + 1e-12, 1e-5)
    v = np.zeros_like(t)
    for s, a in zip((rest, rest + 0.0055, rest + 0.011, rest + 0.0165), (80, 60, 90, 70)):
        rise, fall = (t >= s) & (t < s + 4e-4), (t >= s + 4e-4) & (t < s + 5e-3)
        v[rise] = a * (t[rise] - s) / 4e-4
        v[fall] = a * (1 - (t[fall] - s - 4e-4) / 4.6e-3) ** 1.5
    return idm_rs.Sampled(t, v)


def test_a_sampled_drive_loads_with_its_voltage_as_the_input(tmp_path):
    w = _drive()
    d = make_case(tmp_path / "c", nominal_params=P, model="lps", experiments=[{"sampled": w}], write_noise_rms=True)
    meta = json.loads((d / "meta.json").read_text())
    assert meta["experiments"][0] == {"file": "exp1_sampled.csv", "waveform": "sampled"}
    rec = idm_rs.load_case(d)
    e = rec.experiments[0]
    assert e.is_sampled and e.amplitude_V == 90.0 and e.rest_s == pytest.approx(0.00201)
    assert isinstance(e.waveform, idm_rs.Sampled) and e.duration == pytest.approx(0.024)
    assert rec.noise_rms_m == 1.5e-9 and estimate_noise(rec).sigma == 1.5e-9


def test_noise_without_rest_comes_from_the_high_frequency_content(tmp_path):
    w = _drive(rest=0.0)
    w = idm_rs.Sampled(w.t, w.voltage + 5.0)  # never at 0 V: no rest at all
    d = make_case(tmp_path / "c", nominal_params=P, model="lps", experiments=[{"sampled": w}], noise_rms=2e-9)
    noise = estimate_noise(idm_rs.load_case(d))
    assert noise.n_rest == 0
    assert noise.sigma == pytest.approx(2e-9, rel=0.1)


def test_a_bad_sampled_voltage_is_named(tmp_path):
    d = make_case(tmp_path / "c", nominal_params=P, model="lps", experiments=[{"sampled": _drive()}])
    csv = d / "exp1_sampled.csv"
    lines = csv.read_text().splitlines()
    cells = lines[5].split(",")
    lines[5] = ",".join([cells[0], "nan", cells[2]])
    csv.write_text("\n".join(lines) + "\n")
    with pytest.raises(RecordingError, match="voltage"):
        idm_rs.load_case(d)


# the effect case is slow (64 s on 2 cores): the healthy one keeps the sampled-drive path in the
# default run, tests/test_diagnosis.py an effect named end to end
@pytest.mark.parametrize("kind, verdict", [("misset", "none"),
                                           pytest.param("spring", "spring_to_ground", marks=pytest.mark.slow)])
def test_diagnosis_on_sampled_drives(tmp_path, kind, verdict):
    w = _drive()
    effects = idm_rs.Effects(k_ground=2e4) if kind == "spring" else None
    nominal = P.replace(mu_k=0.54) if kind == "misset" else P
    d = make_case(tmp_path / kind, nominal_params=nominal, true_params=P, model="lps", effects=effects,
                  experiments=[{"sampled": w}, {"sampled": idm_rs.Sampled(w.t, 0.8 * w.voltage)}])
    dg = idm_rs.diagnose(d, progress=False)
    assert dg.verdict == verdict, text_report(dg)
    assert dg.rms_after <= 1.1 * dg.noise.sigma


def test_a_sampled_drive_jacobian_after_a_retried_run_takes_the_passes_alone_at_its_step(tmp_path):
    """A sampled experiment whose run the engine retried at dt/2 (a presliding law too stiff for
    the fit step: 1.8 x fric_beta) gets its Jacobian from the derivative passes alone at dt/2,
    the same bits as the whole request (the run at the fit step, its retry, the passes)."""
    from idm_rs.core.batch import Structure
    from idm_rs.diagnosis.case_model import CaseSimulator, ModelSpec
    from idm_rs.diagnosis.fitting import FreeParam, Objective, apply, set_param
    from idm_rs.io.recording import load_case

    w = _drive()
    rec = load_case(make_case(tmp_path / "c", nominal_params=P, model="lps", experiments=[{"sampled": w}] * 2,
                              noise_rms=1e-9))
    obj = Objective(rec, CaseSimulator(rec), 1e-9)
    params = P.to_dict(resolved=False)
    stiff = ModelSpec(Structure("lps", 1, False), {**params, "fric_beta": 1.8 * params["fric_beta"]}, {})
    free = [FreeParam("m2", P.m2, 0.5 * P.m2, 1.6 * P.m2, 0.05 * P.m2, set_param("m2"))]
    u = np.array([0.1])
    at, steps = obj.predict_checked(apply(stiff, free, u))
    assert steps == [1e-7, 1e-7]
    r0, J0, _ = obj.jacobian(stiff, free, u)
    r1, J1, _ = obj.jacobian(stiff, free, u, at=at, at_steps=steps)
    assert np.array_equal(r0, r1) and np.array_equal(J0, J1) and np.any(J0 != 0.0)
