"""The diagnosis end to end on small cases that idm-rs generates itself (so these run in a user's
clone, without ../shared/recordings): a device with a clear ground spring must be diagnosed as
`spring_to_ground` with the right stiffness, a device whose only difference from the nominal
model is a mis-set friction coefficient as `none`; then the report, the JSON and the plots."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest

import idm_rs
from idm_rs.core.interrupted import interrupted
from idm_rs.diagnosis import plot_diagnosis, text_report
from idm_rs.io.synthetic import make_case

PNG_MAGIC = b"\x89PNG\r\n\x1a\n"
#: nominal model of the synthetic cases: Table 1 with the normal force written out
NOMINAL = idm_rs.Params(normal_force=(0.4 + 0.3) * 9.81)
#: three short bursts at 200 Hz (2 cycles, 12 ms each), both directions
EXPERIMENTS = (
    {"amplitude_V": 80, "frequency_Hz": 200, "direction": "forward", "cycles": 2},
    {"amplitude_V": 60, "frequency_Hz": 200, "direction": "backward", "cycles": 2},
    {"amplitude_V": 100, "frequency_Hz": 200, "direction": "forward", "cycles": 2},
)
NOISE = 1.5e-9
K_GROUND = 2e4  # [N/m]: ~ 20 x noise in the reading before any refit
JSON_KEYS = ("verdict", "ranking", "rms_before", "rms_calibrated", "rms_after", "noise_rms", "locations")
RANKING_KEYS = ("effect", "params", "rms_after", "bic", "heldout_rms")


@pytest.fixture(scope="module")
def spring_case(tmp_path_factory) -> Path:
    return make_case(tmp_path_factory.mktemp("spring") / "spring_case", nominal_params=NOMINAL,
                     effects=idm_rs.Effects(k_ground=K_GROUND), experiments=EXPERIMENTS, noise_rms=NOISE, seed=1,
                     dt=2e-8)


@pytest.fixture(scope="module")
def spring_diagnosis(spring_case) -> idm_rs.Diagnosis:
    return idm_rs.diagnose(spring_case, progress=False)


def test_a_ground_spring_is_named_and_fitted(spring_diagnosis):
    d = spring_diagnosis
    assert d.verdict == "spring_to_ground", text_report(d)
    cand = next(c for c in d.ranking if c.effect == "spring_to_ground")
    assert cand.params["k_ground"] == pytest.approx(K_GROUND, rel=0.25)
    assert d.rms_after <= 1.2 * d.noise.sigma
    # the noise estimate is the one the data was made with
    assert d.noise.sigma == pytest.approx(NOISE, rel=0.15)
    # the missing spring showed before: calibration alone leaves a systematic residual
    assert d.rms_calibrated > 1.2 * d.noise.sigma
    assert any(loc.systematic for loc in d.locations)


def test_the_fit_figures_show_the_reports_residuals(spring_diagnosis):
    from idm_rs.diagnosis.plots import refit_candidate, report_residuals

    d = spring_diagnosis
    pairs = [report_residuals(d, j) for j in range(len(d.recording.experiments))]
    for (cal, ref), e in zip(pairs, d.recording.experiments):
        assert cal.size == ref.size == e.t.size
    pooled = lambda rs: math.sqrt(sum(float(np.sum(r * r)) for r in rs) / sum(r.size for r in rs))  # noqa: E731
    assert pooled([p[0] for p in pairs]) == pytest.approx(d.rms_calibrated, rel=1e-9)
    assert pooled([p[1] for p in pairs]) == pytest.approx(refit_candidate(d).rms_after, rel=1e-9)


def test_a_misset_friction_coefficient_is_not_missing_physics(tmp_path):
    case = make_case(tmp_path / "none_case", nominal_params=NOMINAL, true_params=NOMINAL.replace(mu_k=0.5 * 1.05),
                     experiments=EXPERIMENTS, noise_rms=NOISE, seed=2, dt=2e-8)
    d = idm_rs.diagnose(case, progress=False)
    assert d.verdict == "none", text_report(d)
    # calibration finds the mis-set coefficient and leaves noise
    assert d.calibrated["mu_k"] == pytest.approx(0.525, rel=0.01)
    assert d.rms_before > 3 * d.noise.sigma
    assert d.rms_calibrated <= 1.2 * d.noise.sigma


def test_report_tells_the_story(spring_diagnosis):
    d = spring_diagnosis
    text = text_report(d)
    assert f"VERDICT: {d.verdict.upper()}" in text
    for part in ("noise floor", "nominal model", "calibrated nominal", "Calibrated nominal parameters",
                 "Where the residual lives", "Candidate effects", "Refit model:", " nm", "N/m"):
        assert part in text, part
    for c in d.ranking:
        assert c.effect in text
    # the score, the likelihood ratio and the noise floor's source are shown; every local fit
    # of the calibration is in the JSON
    assert "score" in text and "LR / crit" in text and d.noise.source in text
    js = d.to_dict()
    assert js["calibration"]["multistart"]["local_fits"] and js["screening_scores"]
    assert js["alternatives"] == [a.to_dict() for a in d.alternatives]


def test_the_report_says_it_in_plain_words_first(spring_diagnosis):
    text = text_report(spring_diagnosis)
    plain = text.index("In plain words")
    assert plain < text.index("VERDICT:") < text.index("ΔBIC")
    summary = text[plain:text.index("The numbers behind it")]
    assert "Found: a spring from the main body to the ground" in summary and "k_ground = " in summary
    assert "How sure: overwhelming evidence" in summary and "What to do: add this effect" in summary
    for jargon in ("ΔBIC", "whiteness", "LR", "chi"):
        assert jargon not in summary, jargon


def test_alternatives_are_named_in_report_and_json(spring_diagnosis):
    from dataclasses import replace

    from idm_rs.diagnosis.results import Alternative

    alt = Alternative("incline", 123.0, "its signature is parallel to the leader's (|cos| = 0.999)")
    d = replace(spring_diagnosis, alternatives=[alt])
    assert "ALTERNATIVE: incline (ΔBIC 123): its signature is parallel" in text_report(d)
    assert d.to_dict()["alternatives"] == [{"effect": "incline", "delta_bic": 123.0, "why": alt.why}]
    assert d.verdict == spring_diagnosis.verdict  # the verdict stays the leader


def test_cli_diagnose_writes_report_json_and_plots(spring_case, spring_diagnosis, tmp_path, capsys, monkeypatch):
    """The command line around the diagnosis (the diagnosis itself is the one above, not re-run)."""
    import idm_rs.diagnosis
    from idm_rs.apps.cli import main

    calls = []

    def cached(case, **kw):
        calls.append((Path(case), kw))
        return spring_diagnosis

    monkeypatch.setattr(idm_rs.diagnosis, "diagnose", cached)
    out_json, plots = tmp_path / "out" / "d.json", tmp_path / "plots"
    rc = main(["diagnose", str(spring_case), "--json", str(out_json), "--plots", str(plots), "--no-progress",
               "--threads", "1"])
    assert rc == 0
    assert calls == [(spring_case, {"progress": False, "threads": 1, "discover": True})]
    text = capsys.readouterr().out
    assert "VERDICT:" in text and str(out_json) in text

    data = json.loads(out_json.read_text())  # strict JSON: no NaN
    for key in JSON_KEYS:
        assert key in data, key
    assert data["verdict"] == spring_diagnosis.verdict
    assert len(data["ranking"]) == len(spring_diagnosis.ranking) > 0
    for entry in data["ranking"]:
        for key in RANKING_KEYS:
            assert key in entry, key
        assert isinstance(entry["params"], dict)
        assert entry["heldout_rms"] is None or math.isfinite(entry["heldout_rms"])
    assert data["noise_rms"] == pytest.approx(spring_diagnosis.noise.sigma)
    assert data["locations"] and {"experiment", "phase", "excess_share", "systematic"} <= set(data["locations"][0])

    names = {p.name for p in plots.iterdir()}
    exps = [e.name for e in spring_diagnosis.recording.experiments]
    assert {f"fit_{n}.png" for n in exps} | {"residual_phases.png", "ranking.png", "rms_story.png"} <= names
    for p in plots.iterdir():
        data = p.read_bytes()
        assert data.startswith(PNG_MAGIC) and len(data) > 10_000, p.name


def test_cli_diagnose_refuses_a_malformed_case(tmp_path, capsys):
    from idm_rs.apps.cli import main

    case = tmp_path / "bad"
    case.mkdir()
    (case / "meta.json").write_text("{not json")
    assert main(["diagnose", str(case), "--no-progress"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("error: ") and "meta.json" in err[0]
    assert main(["diagnose", str(tmp_path / "absent"), "--no-progress"]) == 2


@pytest.mark.slow
def test_cli_diagnose_end_to_end(tmp_path):
    """`python -m idm_rs diagnose` as a user runs it, on a fresh small case."""
    import subprocess
    import sys

    case = make_case(tmp_path / "case", nominal_params=NOMINAL, effects=idm_rs.Effects(k_ground=K_GROUND),
                     experiments=EXPERIMENTS, noise_rms=NOISE, seed=3, dt=2e-8)
    out = tmp_path / "d.json"
    proc = subprocess.run([sys.executable, "-m", "idm_rs", "diagnose", str(case), "--json", str(out), "--plots",
                           str(tmp_path / "plots"), "--no-progress"], capture_output=True, text=True, timeout=600)
    assert proc.returncode == 0, proc.stderr
    data = json.loads(out.read_text())
    assert data["verdict"] == "spring_to_ground"
    assert (tmp_path / "plots" / "ranking.png").exists()


def test_every_blas_runs_on_one_thread_whatever_the_caller_imported_before(spring_case):
    """threadpoolctl limits only the libraries loaded when the limit is set; scipy.linalg loads
    its own OpenBLAS, which the first fit used to load inside the limit, on every core:
    discovery's large least squares then depended on what the caller had imported and on the
    machine's core count. In a fresh process that has not imported it, every BLAS the stages see runs on one
    thread."""
    import subprocess
    import sys

    script = f"""
import importlib
import sys
import idm_rs
dg = importlib.import_module("idm_rs.diagnosis.diagnose")
assert "scipy.linalg" not in sys.modules  # what made the bug: loaded only later, inside the limit
seen = []

class Stop(Exception):
    pass

def stage(s):
    from threadpoolctl import threadpool_info
    seen.extend((i["filepath"], i["num_threads"]) for i in threadpool_info() if i["user_api"] == "blas")
    raise Stop

dg.PIPELINE = (("probe", stage),)
try:
    idm_rs.diagnose({str(spring_case)!r}, progress=False)
except Stop:
    pass
print(seen)
assert any("scipy_openblas-" in f for f, _ in seen) and all(n == 1 for _, n in seen), seen
"""
    proc = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stdout + proc.stderr


def test_report_shows_unsupported_candidates_as_such(spring_diagnosis):
    """A candidate no better than the nominal model it contains is "not supported", not a huge
    negative ΔBIC."""
    import copy

    d = copy.copy(spring_diagnosis)
    worse = copy.copy(d.ranking[-1])
    worse.delta_bic = -93_000.0
    d.ranking = list(d.ranking[:-1]) + [worse]
    text = text_report(d)
    assert "not supported" in text and "-93000" not in text


def test_progress_advances_by_stage_to_the_end():
    from idm_rs.diagnosis.progress import STAGES, Progress

    runs = [0]
    p = Progress("test", lambda: runs[0])  # the bar shows the simulator's count of runs
    runs[0] = 40_000  # 10,000 model evaluations of 4 experiments
    p.update(10_000)  # far beyond the stage's typical count: approaches, never passes, its share
    assert STAGES[0][1] * 0.99 < p.bar.n <= STAGES[0][1]
    p.stage_done("calibration")
    assert p.bar.n == pytest.approx(STAGES[0][1])
    p.stage_done("candidate fits")  # a skipped stage's share is passed over
    assert p.bar.n == pytest.approx(sum(s[1] for s in STAGES[:3]))
    assert "null refits" in p.bar.postfix and "40000 simulated runs" in p.bar.postfix
    assert p.bar.smoothing == 0  # the ETA from the whole run's rate
    p.close()
    assert p.bar.n == pytest.approx(100.0)


def test_the_parts_of_stages_are_timed_with_their_runs_nested_under_their_names():
    """`part` adds seconds, simulated runs and calls to the active clock under the names of the
    parts it is in; with no clock active it times nothing."""
    import time

    from idm_rs.diagnosis.progress import Clock, part

    runs = [0]
    clock = Clock(None, lambda: runs[0])
    with part("outside"):  # no clock active: nothing recorded anywhere
        runs[0] += 5
    with clock.active():
        for _ in range(2):
            with part("round"):
                runs[0] += 10
                with part("wide search"):
                    runs[0] += 7
                    time.sleep(0.01)
    assert set(clock.parts) == {"round", "round / wide search"}
    seconds, sims, calls = clock.parts["round / wide search"]
    assert (sims, calls) == (14, 2) and seconds >= 0.02
    assert clock.parts["round"][1:] == [34, 2] and clock.parts["round"][0] >= seconds
    assert clock.timings == {}  # parts are not stages


def test_a_diagnosis_reports_the_parts_of_its_stages(spring_diagnosis):
    d = spring_diagnosis
    assert d.to_dict()["timings_parts"] == d.timings_parts
    for seconds, sims, calls in d.timings_parts.values():
        assert seconds >= 0 and sims >= 0 and calls >= 1
    # every part lies within the run, and a nested part within its parent
    for name, (seconds, _, _) in d.timings_parts.items():
        assert seconds <= d.seconds
        if " / " in name:
            assert seconds <= d.timings_parts[name.rsplit(" / ", 1)[0]][0] + 1e-9


def test_ctrl_c_keeps_what_was_finished(spring_case, tmp_path, capsys, monkeypatch):
    """Ctrl-C during the calibration: the nominal model's misfit is kept, the result is marked
    incomplete, the report says so in plain words, the CLI writes the JSON and exits 130."""
    import importlib

    from idm_rs.apps.cli import main

    module = importlib.import_module("idm_rs.diagnosis.diagnose")  # the module, not the function

    def stop(*args, **kwargs):
        raise KeyboardInterrupt

    monkeypatch.setattr(module, "calibrate_null", stop)
    with pytest.raises(KeyboardInterrupt, match="during the calibration") as stopped:
        idm_rs.diagnose(spring_case, progress=False)
    d = idm_rs.partial_result(stopped.value)
    assert d.verdict == "interrupted" and not d.complete
    assert "stopped by Ctrl-C during the calibration" in d.reason
    assert d.rms_before > 0 and math.isnan(d.rms_calibrated) and d.ranking == []
    text = text_report(d)
    assert "Found: no answer yet" in text and "run it again" in text
    out = tmp_path / "d.json"
    assert main(["diagnose", str(spring_case), "--json", str(out), "--no-progress"]) == 130
    data = json.loads(out.read_text())
    assert data["complete"] is False and data["verdict"] == "interrupted"
    assert "what was finished" in capsys.readouterr().err


def test_the_report_prints_the_refit_model_whole(spring_diagnosis):
    """'Add this effect with the fitted values (the refit model below)': below are the effect's
    and every refitted nominal parameter with units, ±1σ and [at bound], not the null's values."""
    from idm_rs.diagnosis.report_format import at_bound, pm, unit_of
    from idm_rs.diagnosis.thresholds import CALIBRATED

    d = spring_diagnosis
    cand = d.verdict_candidate
    tail = text_report(d).split("Refit model:")[1].split("every fitted parameter")[1]
    assert "k_ground" in tail and "N/m" in tail
    assert set(cand.calibrated_std) == set(CALIBRATED)
    for name, v in cand.calibrated.items():
        row = next(line for line in tail.splitlines() if line.strip().startswith(name + " "))
        assert pm(v, cand.calibrated_std[name], unit_of(name)) in row, row
    ranked = next(c for c in d.to_dict()["ranking"] if c["effect"] == "spring_to_ground")
    assert set(ranked["calibrated_std"]) == set(CALIBRATED)
    # a bounded fit stops just inside its bound: still at the bound (sigma1 at +49.97 %)
    assert at_bound(1.4997 * 111.0, 0.6 * 111.0, 1.5 * 111.0) and not at_bound(1.45 * 111.0, 0.6 * 111.0, 1.5 * 111.0)


def test_an_interrupted_diagnosis_reports_and_plots_only_what_finished(spring_case, tmp_path, capsys, monkeypatch):
    """Ctrl-C after the calibration: no invented refit model or time windows in the report, the
    figures of what finished written (--plots is not skipped), exit code 130 as every command."""
    import importlib

    from idm_rs.apps.cli import main

    module = importlib.import_module("idm_rs.diagnosis.diagnose")

    def stop(*args, **kwargs):
        raise KeyboardInterrupt

    monkeypatch.setattr(module, "screen_candidates", stop)
    with pytest.raises(KeyboardInterrupt) as stopped:
        idm_rs.diagnose(spring_case, progress=False)
    d = idm_rs.partial_result(stopped.value)
    assert not d.complete and math.isfinite(d.rms_calibrated)
    text = text_report(d)
    assert "unexplained" not in text and "no systematic time window" not in text
    assert "Refit model:\n  not reached (interrupted before a verdict)" in text
    assert "time windows: not computed (interrupted)" in text and "held-out : calibrated" not in text
    assert "Candidate effects: none fitted before the interrupt" in text
    names = sorted(p.name for p in plot_diagnosis(d, tmp_path / "figs"))
    assert names == sorted([f"fit_{e.name}.png" for e in d.recording.experiments]
                           + ["residual_phases.png", "rms_story.png"]), names
    # the command line on the same result (one interrupted run is enough: minutes of CI)
    def stopped_diagnose(*args, **kwargs):
        raise interrupted("diagnose interrupted", partial=d)

    monkeypatch.setattr(importlib.import_module("idm_rs.diagnosis"), "diagnose", stopped_diagnose)
    assert main(["diagnose", str(spring_case), "--plots", str(tmp_path / "cli"), "--no-progress"]) == 130
    assert "figures (of what finished before the interrupt)" in capsys.readouterr().out


def test_the_ranking_table_and_figure_show_the_same_numbers(spring_diagnosis, tmp_path, monkeypatch):
    """Before: every score-only row read "~ RMS 2.71 x noise (linearised estimate)", the null's
    RMS, not the candidate's; a ΔBIC "not supported" in the table was drawn at -8 in the figure.
    Now a candidate never fitted shows no RMS, and both show the same ΔBIC words."""
    import importlib

    plots = importlib.import_module("idm_rs.diagnosis.plots")
    figures = []
    real_save = plots._save
    monkeypatch.setattr(plots, "_save", lambda fig, path: (figures.append(fig), real_save(fig, path))[1])
    d = spring_diagnosis
    plots.plot_ranking(d, tmp_path)
    notes = [t.get_text() for t in figures[0].axes[0].texts]
    table = text_report(d).split("Candidate effects")[1]
    sigma = d.noise.sigma
    for c, note in zip(d.ranking, notes):
        assert note.startswith(f"ΔBIC {c.delta_bic_words}, "), (c.effect, note)
        row = next(line for line in table.splitlines() if f" {c.effect} " in line)
        assert c.delta_bic_words in row, (c.effect, row)
        if c.screened_only:
            assert "not fitted (score" in note and "RMS" not in note
            assert math.isnan(c.rms_over_noise(sigma))
        else:
            assert f"RMS {c.rms_after / sigma:.2f}× noise" in note and f"{c.rms_after / sigma:.2f} ×" in row


def test_the_diagnosis_figures_keep_their_legends_off_the_data(spring_diagnosis, tmp_path, saved):
    """The fit figure's residual panel and the ranking figure's last row were under a legend."""
    from test_figure_legends import _covered

    plot_diagnosis(spring_diagnosis, tmp_path)
    assert len(saved) >= 3
    for fig in saved:
        assert _covered(fig) == [], fig.axes[0].get_title()


def test_the_bar_is_not_at_100_percent_while_discovery_runs():
    """Before: discovery sat at "100% [06:00<00:00]" for six more minutes. An optional stage that
    starts lengthens the bar; one that is skipped leaves it as it was."""
    from idm_rs.diagnosis.progress import OPTIONAL_SHARE, Progress

    p = Progress("test")
    p.stage_done("held-out")
    assert p.bar.n == pytest.approx(100.0) and p.bar.total == pytest.approx(100.0)
    p.update(20)  # the verdict's work: the bar waits
    assert p.bar.total == pytest.approx(100.0)
    p.stage_begins("discovery")  # the second and third effects were skipped: nothing ran in them
    p.update(50)
    total = 100.0 + OPTIONAL_SHARE["discovery"]
    assert p.bar.total == pytest.approx(total) and 100.0 < p.bar.n < total
    assert p.bar.n / p.bar.total < 0.8  # the percentage the user reads
    p.stage_done("discovery")
    assert p.bar.n == pytest.approx(total)
    p.close()
    assert p.bar.n == pytest.approx(p.bar.total)
