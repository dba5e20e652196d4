"""Measured friction data: the loaders, EMPS identification against the benchmark's published
reference model, and identification of simulated rig data with known parameters (no data
needed). The data sets are not part of the project: tests that need them skip without them."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

import idm_rs
from idm_rs.core.batch import Rig
from idm_rs.rigs import RealDataError, RigData, load
from idm_rs.rigs.fit import EMPS_REFERENCE, idim_ls, rig_fit

REAL = Path(__file__).resolve().parents[2] / "shared" / "realdata"
needs_data = pytest.mark.skipif(not REAL.exists(), reason="the measured data sets (../shared/realdata) are absent")


@needs_data
def test_emps_loads_in_si_units():
    d = load(REAL / "emps" / "DATA_EMPS.mat")
    assert d.rig == "emps" and d.t.size == 24841 and d.t[0] == 0.0
    assert d.sample_rate_Hz == pytest.approx(1000.0, rel=1e-3)
    assert 0.2 < d.response.max() < 0.3  # metres
    assert d.meta["gtau_N_per_V"] == pytest.approx(35.15, rel=1e-3)
    assert np.abs(d.force).max() < 10 * d.meta["gtau_N_per_V"]
    pulses = load(REAL / "emps" / "DATA_EMPS_PULSES.mat")
    assert "pulses_N" in pulses.meta


@needs_data
def test_spring_slider_and_frame_load_in_si_units():
    s = load(REAL / "ensl_paper_stickslip" / "k168Nm_v42.mat")
    assert s.rig == "spring_slider" and s.meta["stiffness_N_per_m"] == 168.0
    assert s.meta["drive_speed_m_per_s"] == pytest.approx(42e-6)
    assert s.sample_rate_Hz == pytest.approx(2000.0, rel=1e-3)
    assert 0.0 < np.median(s.response) < 1.0  # N: about mu m g for a 30.7 g slider
    f = load(REAL / "marino_frame_friction" / "s_b_350g_y.mat")  # either file of the pair
    assert f.rig == "frame" and f.name == "s_b_350g" and f.meta["disc_mass_kg"] == pytest.approx(0.35)
    assert f.sample_rate_Hz == pytest.approx(250.0, rel=1e-3)
    assert np.abs(f.drive).max() < 0.05  # metres, not millimetres


def test_unknown_files_are_refused_by_name(tmp_path):
    with pytest.raises(RealDataError, match="no such file"):
        load(tmp_path / "DATA_EMPS.mat")
    bad = tmp_path / "other.mat"
    bad.write_bytes(b"")
    with pytest.raises(RealDataError, match="not a known data set"):
        load(bad)


@needs_data
def test_emps_identification_matches_the_benchmark_reference(tmp_path, capsys):
    from idm_rs.apps.cli import main

    out = tmp_path / "emps.json"
    assert main(["rig-fit", str(REAL / "emps" / "DATA_EMPS.mat"), "--json", str(out), "--plots", str(tmp_path)]) == 0
    fit = json.loads(out.read_text())
    assert fit["rig"] == "emps" and set(fit["params"]) >= {"m", "fc", "fv", "offset"}
    for k, ref in EMPS_REFERENCE.items():
        assert abs(fit["params"][k] - ref) < 3 * fit["params_std"][k] + 1e-3 * abs(ref), k
    assert fit["rms"] > fit["noise_rms"] > 0
    assert 0 < fit["metrics"]["force_relative_error_pct"] < 8.0
    assert (tmp_path / "rig_fit_DATA_EMPS.png").exists()


def test_identification_recovers_known_parameters_from_simulated_servo_data():
    """A servo rig simulated by the engine (closed loop, Coulomb + viscous friction, an offset
    force), measured at 1 kHz with 1 µm encoder noise: the inverse-model fit recovers them."""
    truth = {"m": 80.0, "fc": 15.0, "fv": 150.0, "offset": -2.0}
    rng = np.random.default_rng(3)
    t = np.arange(0.0, 8.0, 1e-3)
    ref = 0.1 * (1 - np.cos(2 * np.pi * t / 4.0)) + 0.01 * np.sin(2 * np.pi * 1.3 * t)
    p = idm_rs.Params(m1=truth["m"], normal_force=1.0, mu_k=truth["fc"], mu_s=truth["fc"], sigma2=truth["fv"],
                      sigma1=0.0, fric_alpha=1e8, fric_beta=1e8 / (100 * truth["fc"]), fric_gamma=0.0,
                      load_force=-truth["offset"])
    rig = Rig("closed_loop", kp=160.0, kv=240.0, gain=35.0, limit=10.0)
    r = idm_rs.simulate(p, idm_rs.Sampled(t, ref), t_end=float(t[-1]), model=rig, piezo_hysteresis=False,
                        method="rodas4", rtol=1e-8, atol=1e-8, save_every=1, first_step=1e-5)
    q = np.interp(t, r.t, r.main_body)
    v = np.interp(t, r.t, r.main_body_velocity)
    force = 35.0 * np.clip(240.0 * (160.0 * (ref - q) - v), -10, 10)
    meta = {"kp_per_s": 160.0, "kv_V_s_per_m": 240.0, "gtau_N_per_V": 35.0, "saturation_V": 10.0}
    data = RigData("emps", "synthetic", t, ref, q + 1e-6 * rng.standard_normal(t.size), force, meta)
    values, std, *_ = idim_ls(data)
    for k, v_true in truth.items():
        assert values[k] == pytest.approx(v_true, rel=0.05, abs=0.3), k


@needs_data
def test_frame_friction_scales_with_the_normal_load():
    """The four discs load the contact with 250-550 g: the identified Fc/k grows with the load
    while the frame's own mode (f0) stays, and Fc/(k N) is one contact property (within 10 %)."""
    fits = [rig_fit(load(REAL / "marino_frame_friction" / f"s_b_{w}g_x.mat"), simulate=False)
            for w in (250, 350, 450, 550)]
    fc_k = [f.params["fc_over_k_m"] for f in fits]
    assert all(np.diff(fc_k) > 0)
    f0 = [f.params["f0_Hz"] for f in fits]
    assert max(f0) / min(f0) < 1.05
    mu = [f.params["mu_over_k_m_per_N"] for f in fits]
    assert max(mu) / min(mu) < 1.15
    assert "k" in fits[0].not_identifiable and "m" in fits[0].not_identifiable


def test_frame_identification_recovers_a_simulated_frame():
    """A base-excited frame simulated by the engine (f0 = 3 Hz, 3 % damping, Fc/k = 0.8 mm,
    1 Hz base motion of 1.8 mm), sampled at 250 Hz: the identification returns them."""
    from idm_rs.rigs.fit import fit_frame

    m, f0, zeta, fc_k = 1.0, 3.0, 0.03, 0.8e-3
    k = m * (2 * np.pi * f0) ** 2
    c, fc = 2 * zeta * np.sqrt(k * m), fc_k * k
    a = 1e3 * k
    p = idm_rs.Params(m1=m, normal_force=1.0, mu_s=fc, mu_k=fc, stribeck_velocity=1e-4, sigma2=0.0, sigma1=0.0,
                      fric_alpha=a, fric_beta=a / (100 * fc), fric_gamma=0.0)
    t = np.arange(0.0, 10.0, 4e-3)
    y = 1.8e-3 * np.sin(2 * np.pi * 1.0 * t)
    r = idm_rs.simulate(p, idm_rs.Sampled(t, y), t_end=float(t[-1]), model=Rig("position", stiffness=k, damping=c),
                        piezo_hysteresis=False, method="rodas4", rtol=1e-8, atol=1e-8, save_every=1, first_step=1e-5)
    x = np.interp(t, r.t, r.main_body)
    data = RigData("frame", "synthetic", t, y, x, None, {"disc_mass_kg": 0.1, "disc_weight_N": 0.981})
    fit = fit_frame(data, simulate=False)
    assert fit.params["f0_Hz"] == pytest.approx(f0, rel=0.03)
    assert fit.params["fc_over_k_m"] == pytest.approx(fc_k, rel=0.05)
    assert fit.params["zeta"] == pytest.approx(zeta, abs=0.02)


def test_spring_slider_features_recover_known_static_and_kinetic_friction():
    """A spring–slider simulated by the engine (30.7 g, 1002 N/m, 1.1 mm/s, μs = 0.36, μk = 0.30)
    sampled at 2 kHz with the data set's spike-like noise: the stick-slip features give μs and μk
    back (to 2 %: with constant kinetic friction the slip swings symmetrically about Fc)."""
    from idm_rs.rigs.data import ENSL_SLIDER_MASS, GRAVITY
    from idm_rs.rigs.fit import fit_spring_slider

    n_force, k, speed = ENSL_SLIDER_MASS * GRAVITY, 1002.0, 1.1e-3
    a = 1e7
    p = idm_rs.Params(m1=ENSL_SLIDER_MASS, normal_force=n_force, mu_s=0.36, mu_k=0.30, stribeck_velocity=1e-4,
                      sigma2=0.0, sigma1=0.0, fric_alpha=a, fric_beta=a / (100 * 0.36 * n_force), fric_gamma=0.0)
    t = np.arange(0.0, 2.0, 5e-4)
    r = idm_rs.simulate(p, idm_rs.Sampled([0.0, 2.0], [0.0, 2.0 * speed]), t_end=2.0,
                        model=Rig("position", stiffness=k), piezo_hysteresis=False, method="rodas4", rtol=1e-8,
                        atol=1e-8, save_every=1, first_step=1e-6)
    force = k * (speed * t - np.interp(t, r.t, r.main_body))
    rng = np.random.default_rng(1)
    spikes = np.where(rng.random(t.size) < 0.002, 0.05 * rng.standard_normal(t.size), 0.0)
    meta = {"stiffness_N_per_m": k, "drive_speed_m_per_s": speed, "mass_kg": ENSL_SLIDER_MASS,
            "normal_force_N": n_force}
    data = RigData("spring_slider", "synthetic", t, speed * t, force + spikes, force + spikes, meta)
    fit = fit_spring_slider(data, simulate=False)
    assert fit.metrics["slip_events"] >= 5
    assert fit.params["mu_s"] == pytest.approx(0.36, rel=0.02)
    assert fit.params["mu_k"] == pytest.approx(0.30, rel=0.02)


@needs_data
def test_spring_slider_record_gives_plausible_paper_on_paper_friction():
    fit = rig_fit(load(REAL / "ensl_paper_stickslip" / "k1002Nm_v42.mat"))
    assert fit.metrics["slip_events"] > 100
    assert 0.25 < fit.params["mu_k"] < fit.params["mu_s"] < 0.45
    assert "stribeck_velocity" in " ".join(fit.not_identifiable)


# --- diagnosis on rig data -----------------------------------------------------------------------


def _servo_regression(ripple: float, seed: int = 0):
    """Inverse-model rows of a servo stroke (a, v, q) with Coulomb + viscous friction, an offset,
    white force noise of 1 N and, if ``ripple`` [N], a cogging force of 20 mm wavelength."""
    rng = np.random.default_rng(seed)
    t = np.arange(0.0, 20.0, 5e-3)
    q = 0.12 * (1 - np.cos(2 * np.pi * t / 5.0)) + 0.004 * np.sin(2 * np.pi * 0.9 * t)
    v = np.gradient(q, t)
    a = np.gradient(v, t)
    force = 90 * a + 200 * v + 20 * np.sign(v) - 3 + ripple * np.sin(2 * np.pi * q / 0.02 + 0.4)
    return t, q, v, a, force + rng.standard_normal(t.size)


@pytest.mark.parametrize("ripple, verdict", [(0.0, "none"), (1.5, "cogging")])
def test_rig_diagnosis_names_a_ripple_and_stays_quiet_without_one(ripple, verdict):
    from idm_rs.rigs.diagnosis import _linear_rig

    t, q, v, a, force = _servo_regression(ripple)
    X0 = np.column_stack([a, v, np.sign(v), np.ones_like(v)])
    d = _linear_rig("emps", "synthetic", X0, force, q, v, 1.0, t)
    assert d.verdict == verdict, d.report()
    if verdict == "cogging":
        best = d.ranking[0]
        lam = float(best.setting.split("=")[1].split()[0])
        assert lam == pytest.approx(20.0, rel=0.01)  # mm
        assert d.rms_after == pytest.approx(1.0, rel=0.05)  # back to the noise


@needs_data
def test_cli_diagnoses_a_rig_data_file(tmp_path, capsys):
    from idm_rs.apps.cli import main

    out = tmp_path / "d.json"
    assert main(["diagnose", str(REAL / "emps" / "DATA_EMPS.mat"), "--json", str(out)]) == 0
    d = json.loads(out.read_text())
    # the documented result (docs/realdata/EMPS.md): a force of the position, ΔBIC 964
    assert d["rig"] == "emps" and d["verdict"] == "position_force"
    assert d["ranking"][0]["effect"] == "position_force"
    assert d["ranking"][0]["delta_bic"] == pytest.approx(964.2, abs=0.5)
    assert "Where the residual lives" in capsys.readouterr().out
