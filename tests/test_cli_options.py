"""What was untested (issue 20, item 24): the simulate/sweep options, rig-fit without simulation
on the spring-slider and frame records, each rig effect on data made with it, Ctrl-C in the
command line and in characterize, and the Dask block size and thread setting."""

from __future__ import annotations

import math
import warnings
from pathlib import Path

import numpy as np
import pytest
import xarray as xr

import idm_rs
from conftest import interrupt_main_when
from idm_rs.apps.cli import main
from idm_rs.core.interrupted import interrupted
from idm_rs.core.units import si
from idm_rs.rigs import RigData
from idm_rs.rigs.diagnosis import _linear_rig, diagnose_spring_slider

REAL = Path(__file__).resolve().parents[2] / "shared" / "realdata"
needs_real = pytest.mark.skipif(not REAL.exists(), reason="the measured data sets are not here")
P = idm_rs.Params()


def test_simulate_options_reach_the_run(tmp_path, capsys):
    out = tmp_path / "r.nc"
    assert main(["simulate", "--model", "dps", "--n-elements", "3", "--dt", "2e-8", "--t-end", "1e-3", "--save-every",
                 "7", "--amplitude", "60", "--rise", "2e-4", "--fall", "8e-4", "--no-hysteresis",
                 "--out", str(out)]) == 0
    api = idm_rs.simulate(P, idm_rs.Triangle(60.0, 2e-4, 8e-4), t_end=1e-3, dt=2e-8, model="dps", n_elements=3,
                          save_every=7, piezo_hysteresis=False)
    with xr.open_dataset(out) as ds:
        assert ds.attrs["n_elements"] == 3 and ds.sizes["time"] == api.t.size and ds.sizes["node"] == 4
        np.testing.assert_array_equal(ds["main_body"].values, api.main_body)
    assert si(api.final_position, "m", 7) in capsys.readouterr().out


def test_sweep_method_options_reach_the_dataset(tmp_path):
    out = tmp_path / "s.nc"
    assert main(["sweep", "--model", "lps", "--grid", "voltage=40,80", "--t-end", "1e-3", "--method", "dopri5",
                 "--rtol", "1e-6", "--atol", "2e-6", "--first-step", "1e-9", "--retries", "0", "--threads", "1",
                 "--no-progress", "--out", str(out)]) == 0
    with xr.open_dataset(out) as ds:
        a = ds.attrs
        assert (a["method"], a["rtol"], a["atol"], a["first_step_s"], a["retries"]) == ("dopri5", 1e-6, 2e-6, 1e-9, 0)
        assert a["executor"] == "local rayon, 1 threads"
        ref = idm_rs.sweep(P, idm_rs.Triangle(), {"voltage": [40.0, 80.0]}, t_end=1e-3, model="lps", method="dopri5",
                           rtol=1e-6, atol=2e-6, first_step=1e-9, progress=False)
        np.testing.assert_array_equal(ds.final_position.values, ref.final_position.values)


@needs_real
@pytest.mark.parametrize("path, judged", [
    ("ensl_paper_stickslip/k1002Nm_v42.mat", "The identified model was not judged against the record"),
    ("marino_frame_friction/s_b_450g_x.mat", "The identified model describes the record"),
])
def test_rig_fit_without_simulation(path, judged, tmp_path, capsys):
    out = tmp_path / "f.json"
    assert main(["rig-fit", str(REAL / path), "--no-simulation", "--json", str(out)]) == 0
    text = capsys.readouterr().out
    assert judged in text
    import json

    d = json.loads(out.read_text())
    assert "simulated_period_s" not in d["metrics"] and "position_relative_error_pct" not in d["metrics"]
    assert d["describes"] is (None if "not judged" in judged else True)


def _stroke(seed: int = 1):
    rng = np.random.default_rng(seed)
    t = np.arange(0.0, 20.0, 5e-3)
    q = 0.12 * (1 - np.cos(2 * np.pi * t / 5.0)) + 0.004 * np.sin(2 * np.pi * 0.9 * t)
    v = np.gradient(q, t)
    a = np.gradient(v, t)
    return t, q, v, a, rng.standard_normal(t.size)


@pytest.mark.parametrize("effect", ["stribeck_peak", "position_dependent", "position_force"])
def test_each_rig_effect_is_named_on_data_made_with_it(effect):
    t, q, v, a, noise = _stroke()
    u = (q - 0.5 * (q.max() + q.min())) / (0.5 * np.ptp(q))
    extra = {"stribeck_peak": 4.0 * np.exp(-((v / 1e-2) ** 2)) * np.sign(v),
             "position_dependent": 3.0 * u * np.sign(v),
             "position_force": 3.0 * u ** 2 + 2.0 * u ** 3}[effect]
    force = 90 * a + 200 * v + 20 * np.sign(v) - 3 + extra + noise
    X0 = np.column_stack([a, v, np.sign(v), np.ones_like(v)])
    d = _linear_rig("emps", "synthetic", X0, force, q, v, 1.0, t)
    assert d.verdict == effect, d.report()
    assert d.rms_after == pytest.approx(1.0, rel=0.05)


def test_stick_time_aging_is_named_on_a_slider_record_made_with_it():
    """A spring-slider record whose slip onsets grow with ln(stick time): Fs = 0.1 + 0.004 ln(t_stick) N."""
    rng = np.random.default_rng(2)
    fs_rate, pieces_t, pieces_f, t0 = 2000.0, [], [], 0.0
    for _ in range(120):
        stick = float(rng.uniform(0.1, 2.0))
        peak = 0.1 + 0.004 * math.log(stick)
        n = int(stick * fs_rate)
        pieces_t.append(t0 + np.arange(n) / fs_rate)
        pieces_f.append(np.linspace(0.07, peak, n))
        t0 += n / fs_rate
    t, f = np.concatenate(pieces_t), np.concatenate(pieces_f)
    f = f + 2e-4 * rng.standard_normal(t.size)
    data = RigData("spring_slider", "synthetic", t, 1e-4 * t, f, f,
                   {"stiffness_N_per_m": 1000.0, "drive_speed_m_per_s": 1e-4, "mass_kg": 0.03, "normal_force_N": 0.3})
    d = diagnose_spring_slider(data)
    assert d.verdict == "stick_time_aging", d.report()
    beta = next(c for c in d.ranking if c.effect == "stick_time_aging").values["beta_N"]
    assert beta == pytest.approx(0.004, rel=0.1)


def test_ctrl_c_in_the_simulate_command_keeps_the_trajectory(tmp_path, capsys, monkeypatch):
    import importlib
    import threading

    started = threading.Event()
    engine = importlib.import_module("idm_rs.core.simulation").engine
    real = engine.simulate
    monkeypatch.setattr(engine, "simulate", lambda *a: (started.set(), real(*a))[1])
    out = tmp_path / "r.csv"
    interrupter = interrupt_main_when(started.is_set, delay=0.5)
    with warnings.catch_warnings():
        warnings.simplefilter("default")  # as outside pytest: the CLI prints them as one line
        rc = main(["simulate", "--model", "lps", "--t-end", "2", "--save-every", "100000", "--out", str(out)])
    interrupter.join()
    assert rc == 130  # the same exit code as every other command stopped by Ctrl-C
    cap = capsys.readouterr()
    assert "interrupted at t = " in cap.out and "last position" in cap.out
    rows = np.loadtxt(out, delimiter=",", skiprows=1)
    assert 0 < rows[-1, 0] < 2.0


def test_ctrl_c_in_characterize_keeps_what_was_finished(tmp_path, capsys, monkeypatch):
    """The second of characterize's sweeps is stopped: the velocity map is kept, the command
    writes it and exits 130 (no figures, no stall force)."""
    import importlib

    sweep_module = importlib.import_module("idm_rs.sweeps.sweep")
    real = sweep_module.sweep
    calls = []

    def stopped_second(*args, **kw):
        ds = real(*args, **kw)
        calls.append(1)
        if len(calls) == 2:
            ds.attrs["complete"] = 0
            raise interrupted("sweep interrupted", partial=ds)  # as the real one does
        return ds

    monkeypatch.setattr(sweep_module, "sweep", stopped_second)
    with warnings.catch_warnings():
        warnings.simplefilter("default")  # as outside pytest: the CLI prints them as one line
        rc = main(["characterize", "--out", str(tmp_path), "--model", "lps", "--frequencies", "200,500",
                   "--voltages", "80", "--step-voltages", "60,100", "--frequency", "200", "--cycles", "3",
                   "--skip-cycles", "1", "--loads", "4", "--no-progress"])
    assert rc == 130
    cap = capsys.readouterr()
    assert "interrupted: wrote" in cap.out and "with the velocity map, the step curve" in cap.out
    with xr.open_dataset(tmp_path / "characteristics.nc") as ds:
        assert ds.attrs["complete"] == 0 and np.isfinite(ds.mean_velocity.values).all()
        assert math.isnan(ds.attrs["stall_force_N"])
    assert not (tmp_path / "velocity_vs_load.png").exists()


def test_dask_blocks_follow_block_size_and_run_one_thread_each(monkeypatch):
    distributed = pytest.importorskip("dask.distributed")
    import importlib
    import warnings

    backends = importlib.import_module("idm_rs.sweeps.backends")
    monkeypatch.setattr(backends, "DASK_MIN_BLOCK", 2)  # so that a small sweep makes several tasks
    grid = {"voltage": np.linspace(40.0, 120.0, 8)}
    kw = dict(t_end=5e-4, dt=5e-8, model="lps", progress=False)
    local = idm_rs.sweep(P, idm_rs.Triangle(), grid, **kw)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # the cluster's start-up/shut-down chatter is not under test
        with distributed.Client(processes=False, n_workers=1, threads_per_worker=2, dashboard_address=None) as client:
            with distributed.get_task_stream(client) as ts:
                remote = idm_rs.sweep(P, idm_rs.Triangle(), grid, client=client, block_size=3, **kw)
    tasks = [t for t in ts.data if "run_block" in t["key"]]
    assert len(tasks) == 3  # 8 points in blocks of 3
    assert remote.attrs["executor"] == "dask"
    np.testing.assert_array_equal(remote.final_position.values, local.final_position.values)


@pytest.mark.parametrize("flag, expected", [([], True), (["--no-discover"], False)])
def test_diagnose_discovery_option_reaches_the_run(flag, expected, tmp_path, monkeypatch):
    """`idm-rs diagnose` runs discovery by default; --no-discover stops at the catalogue."""
    import idm_rs.diagnosis as diagnosis_module

    class Reached(Exception):
        pass

    seen = {}

    def fake(case, **kw):
        seen.update(kw)
        raise Reached

    monkeypatch.setattr(diagnosis_module, "diagnose", fake)
    with pytest.raises(Reached):
        main(["diagnose", str(tmp_path), "--no-progress", *flag])
    assert seen["discover"] is expected
