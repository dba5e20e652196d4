"""What rig-fit and the rig diagnosis tell a user (issue 20, items 9-12): records with bad samples
refused by name, a noise estimate that survives impulsive noise and quantisation, every fit
judged against its record, and the diagnosis's figures and reasons."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from idm_rs.apps.cli import main
from idm_rs.rigs import RealDataError, diagnose_rig, load, rig_fit
from idm_rs.rigs.signals import robust_noise_rms

REAL = Path(__file__).resolve().parents[2] / "shared" / "realdata"
needs_real = pytest.mark.skipif(not REAL.exists(), reason="the measured data sets are not here")
PNG_MAGIC = b"\x89PNG\r\n\x1a\n"


def _emps_file(path: Path, vir: np.ndarray) -> Path:
    from scipy.io import savemat

    t = np.arange(vir.size) * 1e-3
    savemat(path, {"t": t, "qg": np.sin(t), "qm": np.sin(t), "vir": vir, "gtau": 35.15, "kp": 160.18, "kv": 243.45})
    return path


def test_a_record_with_nan_samples_is_refused_by_name(tmp_path, capsys):
    bad = _emps_file(tmp_path / "DATA_EMPS.mat", np.full(2000, np.nan))
    with pytest.raises(RealDataError, match=r"variable 'vir' has 2,000 non-finite samples \(NaN or inf\) of 2,000, "
                                            r"the first at index 0"):
        load(bad)
    some = np.ones(2000)
    some[700] = np.inf
    with pytest.raises(RealDataError, match="1 non-finite samples .* the first at index 700"):
        load(_emps_file(tmp_path / "DATA_EMPS_PULSES.mat", some))
    assert main(["rig-fit", str(bad)]) == 2
    err = capsys.readouterr().err
    assert err.startswith("error: ") and "'vir'" in err and "nan ± nan" not in err and err.count("\n") == 1


def test_the_noise_estimate_survives_spikes_and_quantisation():
    rng = np.random.default_rng(1)
    t = np.linspace(0.0, 10.0, 20_000)
    slow = 50.0 * np.sin(2 * np.pi * 0.1 * t)  # the signal moves, far slower than the samples
    x = slow + rng.normal(0.0, 1.0, t.size)
    x[rng.choice(t.size, 400, replace=False)] += rng.choice([-40.0, 40.0], 400)  # 2 % impulsive spikes
    assert robust_noise_rms(x) == pytest.approx(1.0, rel=0.08)
    q = 0.25  # a quantised record whose noise is below its step: the quantisation noise
    assert robust_noise_rms(q * np.round(0.3 * t / q)) == pytest.approx(q / math.sqrt(12), rel=1e-9)
    assert math.isnan(robust_noise_rms(np.full(100, 3.0)))


@needs_real
def test_slider_noise_is_estimated_where_it_read_zero():
    # the median-filter spread read 0 on five of the nine runs (quantised, spike-laden records)
    fit = rig_fit(load(REAL / "ensl_paper_stickslip" / "k168Nm_v4300.mat"), simulate=False)
    assert 1e-4 < fit.noise_rms < 1e-3  # N: between the quantisation floor and the slip-to-slip spread
    assert fit.noise_rms < fit.rms


@needs_real
def test_a_fit_that_does_not_reproduce_its_record_says_so(capsys):
    bad = rig_fit(load(REAL / "ensl_paper_stickslip" / "k168Nm_v4300.mat"))
    assert bad.describes is False
    assert "0.0945 s against 0.06875 s measured (+37 %)" in bad.judgement
    good = rig_fit(load(REAL / "ensl_paper_stickslip" / "k1002Nm_v42.mat"))
    assert good.describes is True and "(+1 %)" in good.judgement
    assert main(["rig-fit", str(REAL / "ensl_paper_stickslip" / "k168Nm_v4300.mat")]) == 0
    out = capsys.readouterr().out
    assert "The identified model DOES NOT DESCRIBE the record" in out
    assert "(not a model of this record: see above)" in out
    fs_line = next(ln for ln in out.splitlines() if ln.strip().startswith("fs "))
    assert fs_line.split("(")[0].rstrip().endswith(" N"), fs_line  # units with every number
    assert "residual RMS" in out and "noise RMS 0 " not in out
    assert "_pct" not in out and "_s:" not in out  # every metric in words, with its unit
    assert "simulated stick-slip period: 0.0945 s" in out
    emps = rig_fit(load(REAL / "emps" / "DATA_EMPS.mat"), simulate=False)
    assert emps.describes is True and "inverse model's force" in emps.judgement
    from idm_rs.rigs.fit import METRIC_WORDS

    for fit in (bad, good, emps):
        assert set(fit.metrics) <= set(METRIC_WORDS), set(fit.metrics) - set(METRIC_WORDS)
        assert "In plain words" in fit.report().split("The numbers behind it")[0]


@needs_real
def test_rig_diagnosis_writes_its_figures_and_says_why_a_better_fit_lost(tmp_path, capsys):
    path = REAL / "marino_frame_friction" / "s_b_450g_x.mat"
    assert main(["diagnose", str(path), "--plots", str(tmp_path)]) == 0
    out = capsys.readouterr().out
    assert "VERDICT: POSITION_DEPENDENT" in out
    plain = out.split("The numbers behind it")[0]
    assert "Found: friction that changes along the stroke." in plain and "How sure: overwhelming evidence" in plain
    assert "What to do: add (p1 u + p2 u^2) sgn v" in plain and " m, p2 = " in plain  # the frame's unit: m
    assert ("Not named: stribeck_peak lowers BIC more (by 281), but its amplitude s = -0.000279 has the unphysical "
            "sign") in out
    for name in ("rig_residual_s_b_450g.png", "rig_ranking_s_b_450g.png"):
        assert (tmp_path / name).read_bytes().startswith(PNG_MAGIC)
    assert "wrote 2 figures" in out


@needs_real
def test_the_emps_diagnosis_is_the_documented_one():
    d = diagnose_rig(load(REAL / "emps" / "DATA_EMPS.mat"))
    assert d.verdict == "position_force"
    best = d.ranking[0]
    assert best.effect == "position_force" and best.delta_bic == pytest.approx(964.2, abs=0.5)
    assert d.rms_before == pytest.approx(2.298, abs=1e-3) and d.rms_after == pytest.approx(2.081, abs=1e-3)
    stribeck = next(c for c in d.ranking if c.effect == "stribeck_peak")
    assert stribeck.values["s"] < 0 and "unphysical sign" in stribeck.why_not_named()
