"""The next experiment (diagnosis/next_experiment.py): the drives a lab can run, and the expected
ΔBIC by which one would separate two models — zero for the same model, large for a spring the
other model lacks, and smaller where the other model's parameters can mimic the difference."""

from __future__ import annotations

import math

import numpy as np
import pytest

import idm_rs
from idm_rs.diagnosis.case_model import ModelSpec, Structure
from idm_rs.diagnosis.discovery.library import MAIN_TERMS, WEIGHT_TERMS
from idm_rs.diagnosis.next_experiment import Drive, drives, not_by_drive, separation, virtual_recording
from idm_rs.diagnosis.problem import calibration_params
from idm_rs.io.recording import load_case
from idm_rs.io.synthetic import make_case

NOMINAL = idm_rs.Params(normal_force=(0.4 + 0.3) * 9.81)
EXPERIMENTS = (
    {"amplitude_V": 80, "frequency_Hz": 200, "direction": "forward", "cycles": 2},
    {"amplitude_V": 60, "frequency_Hz": 200, "direction": "backward", "cycles": 2},
)


@pytest.fixture(scope="module")
def rec(tmp_path_factory):
    case = make_case(tmp_path_factory.mktemp("next") / "case", nominal_params=NOMINAL, experiments=EXPERIMENTS,
                     noise_rms=1.5e-9, seed=2, dt=2e-8)
    return load_case(case)


def test_the_drives_stay_within_the_rigs_limits(rec):
    grid = drives(rec)
    assert {d.direction for d in grid} == {"forward", "backward"}
    assert max(d.amplitude_V for d in grid) == 80.0 and min(d.amplitude_V for d in grid) == 8.0
    # frequencies within a factor 4 of the recorded 200 Hz, and the edge fits in the period
    assert {d.frequency_Hz for d in grid} == {50.0, 100.0, 200.0, 400.0, 800.0}
    assert all(d.edge_s < 0.5 / d.frequency_Hz for d in grid)
    v = virtual_recording(rec, [Drive("backward", 60.0, 100.0, 4, 5e-4, 2e-3)])
    e = v.experiments[0]
    assert e.direction == "backward" and e.cycles == 4 and e.t[-1] == pytest.approx(0.002 + 4 / 100.0)
    assert np.all(e.x == 0.0) and v.sample_rate_Hz == rec.sample_rate_Hz


def test_separation_is_zero_for_one_model_and_large_for_a_missing_spring(rec):
    nom = rec.nominal
    p0 = nom.params.to_dict(resolved=False)
    s = Structure(nom.model, nom.n_elements, nom.piezo_hysteresis)
    plain = ModelSpec(s, p0, {})
    spring = ModelSpec(s, p0, {"k_ground": 2e4})
    free = calibration_params(p0)
    one = virtual_recording(rec, [Drive("forward", 80.0, 100.0, 3, 5e-4, 2e-3)])
    sigma = 1.5e-9
    assert separation(one, sigma, (plain, []), (plain, [])) == 0.0
    raw = separation(one, sigma, (spring, []), (plain, []))
    absorbed = separation(one, sigma, (spring, free), (plain, free))
    # a 2e4 N/m spring over micrometres of travel is far beyond the noise, and the calibrated
    # parameters can mimic part of it, never more than all
    assert raw > 1e3
    assert 0.0 < absorbed <= raw
    assert math.isfinite(absorbed)


def test_separations_per_drive_are_one_batch_and_agree_with_one_at_a_time(rec):
    from idm_rs.diagnosis.next_experiment import separations

    nom = rec.nominal
    p0 = nom.params.to_dict(resolved=False)
    s = Structure(nom.model, nom.n_elements, nom.piezo_hysteresis)
    a = (ModelSpec(s, p0, {"k_ground": 2e4}), [])
    b = (ModelSpec(s, p0, {}), [])
    grid = [Drive("forward", 80.0, 100.0, 2, 5e-4, 2e-3), Drive("backward", 40.0, 200.0, 2, 5e-4, 2e-3)]
    both = separations(virtual_recording(rec, grid), 1.5e-9, a, b)
    one = [separation(virtual_recording(rec, [g]), 1.5e-9, a, b) for g in grid]
    assert both == pytest.approx(one, rel=1e-9)


def test_the_drive_that_determines_a_parameter_lowers_its_sigma(rec, monkeypatch):
    """A spring to ground fitted with the calibrated subset: adding the proposed drive's
    Fisher information lowers k_ground's 1-sigma, and no drive of the grid does better (a
    smaller grid than the diagnosis's, for time)."""
    from idm_rs.diagnosis import next_experiment
    from idm_rs.diagnosis.catalogue import by_id
    from idm_rs.diagnosis.next_experiment import propose_for_parameter

    monkeypatch.setattr(next_experiment, "PROPOSAL_AMPLITUDE_SHARES", (0.25, 1.0))
    monkeypatch.setattr(next_experiment, "PROPOSAL_FREQUENCIES", (100.0, 400.0))

    nom = rec.nominal
    p0 = nom.params.to_dict(resolved=False)
    s = Structure(nom.model, nom.n_elements, nom.piezo_hysteresis)
    k = next(ep for ep in by_id("spring_to_ground").params if ep.name == "k_ground").free(2e3)
    free = calibration_params(p0)[:3] + [k]
    spec = ModelSpec(s, p0, {"k_ground": 2e3})
    pp = propose_for_parameter(rec, 1.5e-9, "k_ground", (spec, free))
    assert pp is not None and pp.value == pytest.approx(2e3)
    assert 0 < pp.std_with < pp.std_now
    assert pp.std_with == min(x for _, x in pp.scored)
    assert "to determine k_ground" in pp.words()


def test_the_raw_difference_bounds_the_separation_from_above(rec):
    from idm_rs.diagnosis.next_experiment import raw_differences, separations

    nom = rec.nominal
    p0 = nom.params.to_dict(resolved=False)
    s = Structure(nom.model, nom.n_elements, nom.piezo_hysteresis)
    free = calibration_params(p0)[:3]
    a = (ModelSpec(s, p0, {"k_ground": 2e4}), free)
    b = (ModelSpec(s, p0, {}), free)
    v = virtual_recording(rec, [Drive("forward", 80.0, 100.0, 2, 5e-4, 2e-3),
                                Drive("backward", 40.0, 200.0, 2, 5e-4, 2e-3)])
    raw = raw_differences(v, 1.5e-9, a, b)
    sep = separations(v, 1.5e-9, a, b)
    assert all(0.0 < x <= r * (1 + 1e-9) for x, r in zip(sep, raw))


def _incline_and_its_look_alike(rec, theta=1e-4):
    """An incline and the friction asymmetry that exerts the same force while sliding:
    eps Fc = (m1 + m2 + mPE) g sin(theta) (the incline pulls by -M g sin(theta), the asymmetric
    friction by -(1 + eps sgn v) Fc sgn v = -Fc sgn v - eps Fc)."""
    nom = rec.nominal
    p0 = nom.params.to_dict(resolved=False)
    s = Structure(nom.model, nom.n_elements, nom.piezo_hysteresis)
    mass = nom.params.m1 + nom.params.m2 + nom.params.pe_mass
    fc = nom.params.mu_k * nom.params.effective_normal_force
    eps = mass * 9.81 * math.sin(theta) / fc
    return ModelSpec(s, p0, {"theta_rad": theta}), ModelSpec(s, p0, {"eps": eps})


def test_turning_the_rig_end_for_end_separates_an_incline_from_a_direction_dependent_friction(rec):
    """No drive tells them apart as the rig stands (they differ only while the body sticks);
    turned end for end, gravity along the guide acts the other way in the device's frame and the
    contact's asymmetry does not, so one drive separates them by far more than 10 (theta as on
    d2_12, ~1e-4 rad), and the
    proposal is such a drive, worded for the lab."""
    from idm_rs.diagnosis.next_experiment import orientations_for, propose

    incline, asym = _incline_and_its_look_alike(rec)
    sigma = 1.5e-9
    as_stands = Drive("forward", 80.0, 100.0, 4, 5e-4, 2e-3)
    turned = Drive("forward", 80.0, 100.0, 4, 5e-4, 2e-3, "reversed")
    same = separation(virtual_recording(rec, [as_stands]), sigma, (incline, []), (asym, []))
    apart = separation(virtual_recording(rec, [turned]), sigma, (incline, []), (asym, []))
    assert same < 2.0 and apart > 100.0
    assert orientations_for(asym) == ("normal",) and orientations_for(incline, asym) == ("normal", "reversed")
    p = propose(rec, sigma, ("incline", "friction_asymmetry"), (incline, []), (asym, []))
    assert p is not None and p.separates and p.drive.orientation == "reversed"
    assert p.recorded_delta_bic < 10.0
    assert "turned end for end" in p.words() and p.to_dict()["drive"]["orientation"] == "reversed"


def test_a_reversed_experiment_is_simulated_with_the_bench_fixed_force_turned(tmp_path):
    """The case simulator reads an experiment recorded with the rig turned end for end as the
    synthetic writer (the engine with the incline negated) made it, and its reading's
    derivative in theta is the turned one (checked against a central difference)."""
    from idm_rs.diagnosis.case_model import CaseSimulator

    theta = 3e-3
    exps = [dict(e, cycles=2) for e in EXPERIMENTS[:1]] * 2
    exps[1] = dict(exps[1], orientation="reversed")
    case = make_case(tmp_path / "turned", nominal_params=NOMINAL, effects=idm_rs.Effects(theta_rad=theta),
                     experiments=exps, noise_rms=0.0, resolution=0.0, offsets=[0.0, 0.0], dt=2e-7)
    rec = load_case(case)
    assert [e.orientation for e in rec.experiments] == ["normal", "reversed"]
    nom = rec.nominal
    s = Structure(nom.model, nom.n_elements, nom.piezo_hysteresis)
    p0 = nom.params.to_dict(resolved=False)
    sim = CaseSimulator(rec, dt=2e-7)
    (pred,), (sens,), _ = sim.predict_with_sensitivities([ModelSpec(s, p0, {"theta_rad": theta})], ["theta_rad"])
    for j in range(2):
        assert np.max(np.abs(pred[j] - rec.experiments[j].x)) < 1e-12
    # turned, the incline pulls forward: the body gets further than as the rig stands
    assert pred[1][-1] - pred[1][0] > pred[0][-1] - pred[0][0] + 1e-8
    h = 1e-5
    up, down = (sim.predict([ModelSpec(s, p0, {"theta_rad": theta + d})])[0] for d in (h, -h))
    for j in range(2):
        fd = (up[j] - down[j]) / (2 * h)
        assert np.max(np.abs(sens[j][0] - fd)) < 1e-3 * np.max(np.abs(fd))
    assert np.sign(sens[0][0][-1]) == -np.sign(sens[1][0][-1])


def test_the_drive_that_lets_a_found_periodic_form_pass_the_held_out_check(rec, monkeypatch):
    """A friction periodic in position (6 um; the forward experiment travels 6.7 um, the
    backward 5.1 um): refitted without the held-out forward experiment, the backward one leaves
    the wavelength and phase loose, so the held-out prediction is predicted to fail (> 1.5 x
    noise). The proposed drive brings the predicted held-out RMS to noise; the worst drives are
    the long ones that would themselves be held out (predicting them is an extrapolation over
    several periods from what the others pin down)."""
    from idm_rs.diagnosis import next_experiment
    from idm_rs.diagnosis.fitting import FreeParam, set_effect
    from idm_rs.diagnosis.next_experiment import propose_for_heldout
    from idm_rs.diagnosis.problem import heldout_index

    monkeypatch.setattr(next_experiment, "PROPOSAL_FREQUENCIES", (400.0,))
    nom = rec.nominal
    p0 = nom.params.to_dict(resolved=False)
    s = Structure(nom.model, nom.n_elements, nom.piezo_hysteresis)
    wl = 6e-6
    spec = ModelSpec(s, p0, {"lib_ff_sin": 0.03, "lib_ff_cos": 0.01, "lib_wavelength": wl})
    free = calibration_params(p0)[:3] + [
        FreeParam("lib_ff_sin", 0.03, -0.3, 0.3, 0.003, set_effect("lib_ff_sin")),
        FreeParam("lib_ff_cos", 0.01, -0.3, 0.3, 0.003, set_effect("lib_ff_cos")),
        FreeParam("lib_wavelength", wl, wl / 1.6, wl * 1.6, 0.02, set_effect("lib_wavelength"), log=True)]
    pp = propose_for_heldout(rec, 1.5e-9, "lib_wavelength", (spec, free), heldout_index, cycles=(4, 16),
                             shares=(1.0,))
    assert pp is not None and pp.value == pytest.approx(wl)
    assert len(pp.scored) == 8  # 200 (recorded) and 400 Hz, both directions, 4 and 16 cycles
    assert pp.heldout_now > 1.5
    assert pp.heldout_with == min(x for _, x in pp.scored) < 1.1
    assert pp.std_with < pp.std_now
    assert pp.scored[-1][0].cycles == 16 and pp.scored[-1][1] > pp.heldout_with
    assert "held-out check" in pp.words() and "to determine lib_wavelength" in pp.words()


def test_the_pes_extension_against_the_voltage_is_explained_on_either_body():
    """A force c V and a force of the PE's extension are look-alikes no drive separates on the
    main body and on the weight alike (the weight's term reads x2 - x1, the main body's x1 - x2):
    the proposal says so, and what does separate them, in either order of the pair."""
    extension = [t.symbol for t in MAIN_TERMS + WEIGHT_TERMS if t.variable in ("x1 - x2", "x2 - x1")]
    assert sorted(extension) == ["x1 - x2", "x2 - x1"]
    for sym in extension:
        for names in ((sym, "V"), ("V", sym)):
            hint = not_by_drive(names)
            assert "extension" in hint and "strain gauge" in hint, names
            assert sym in hint
    assert not_by_drive(("v1", "dV/dt")) == ""  # a pair a drive can separate gets no such note
