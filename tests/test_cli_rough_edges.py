"""What a new user trips over on the command line (issue 20, items 1-8): each check runs the
command as the user would and asserts what it prints, writes or refuses."""

from __future__ import annotations

import warnings
from pathlib import Path

import numpy as np
import pytest

import idm_rs
from idm_rs.apps.cli import main
from idm_rs.apps.cli_figures import result_title, sweep_title

ROOT = Path(__file__).resolve().parents[1]


def test_simulate_takes_the_sweeps_method_options_and_equals_the_api(tmp_path, capsys):
    out = tmp_path / "r.csv"
    argv = ["simulate", "--model", "lps", "--t-end", "2e-3", "--method", "dopri5", "--rtol", "1e-6", "--atol", "1e-6",
            "--save-every", "1", "--out", str(out)]
    assert main(argv) == 0
    text = capsys.readouterr().out
    assert "dopri5, rtol = 1e-06, atol = 1e-06" in text
    api = idm_rs.simulate(idm_rs.Params(), idm_rs.Triangle(), t_end=2e-3, model="lps", method="dopri5", rtol=1e-6,
                          atol=1e-6, save_every=1)
    rows = np.loadtxt(out, delimiter=",", skiprows=1)
    assert rows.shape[0] == api.t.size
    assert rows[-1, 2] == api.final_position  # full precision, the same run
    assert main(["simulate", "--model", "lps", "--t-end", "1e-3", "--method", "auto"]) == 0
    assert "auto" in capsys.readouterr().out
    assert main(["simulate", "--first-step", "1e-9", "--t-end", "1e-4"]) == 2
    assert "--first-step is for the adaptive methods" in capsys.readouterr().err


@pytest.mark.parametrize("command", ["rig-fit", "diagnose"])
def test_a_data_file_that_is_not_a_mat_file_is_one_error_line(command, tmp_path, capsys):
    bad = tmp_path / "DATA_EMPS.mat"
    bad.write_text("garbage\n")
    assert main([command, str(bad)]) == 2
    err = capsys.readouterr().err
    assert err.startswith("error: ") and err.count("\n") == 1 and "Traceback" not in err
    assert "cannot read as a MATLAB file" in err and str(bad) in err


def test_warnings_print_as_one_plain_line(capsys):
    with warnings.catch_warnings():
        warnings.simplefilter("default")  # as outside pytest (whose configuration makes warnings errors)
        assert main(["simulate", "--model", "lps", "--t-end", "1e-4", "--param", "mu_s=0.3"]) == 0
    err = capsys.readouterr().err
    lines = [ln for ln in err.splitlines() if ln]
    assert len(lines) == 1 and lines[0].startswith("warning: mu_s = 0.3 is below mu_k"), err
    assert ".py:" not in err and "warnings.warn" not in err


def test_a_negative_number_is_read_as_a_value_and_refused_by_name(capsys):
    with pytest.raises(SystemExit) as exc:
        main(["simulate", "--dt", "-1e-8"])
    assert exc.value.code == 2
    err = capsys.readouterr().err
    assert "argument --dt: must be a positive number, got -1e-8" in err and "expected one argument" not in err
    # a value that may be negative goes through: -8e1 V is the mirrored triangle
    assert main(["simulate", "--model", "lps", "--t-end", "1e-3", "--amplitude", "-8e1"]) == 0
    neg = capsys.readouterr().out
    assert main(["simulate", "--model", "lps", "--t-end", "1e-3"]) == 0
    pos = capsys.readouterr().out
    x = lambda text: float(text.split("= ")[-1].split(" µm")[0])  # noqa: E731
    assert x(neg) < 0 < x(pos)


@pytest.mark.parametrize("metric", ["mean_velocity", "backslip", "step_per_cycle"])
def test_a_train_metric_on_a_triangle_is_refused_by_name(metric, tmp_path, capsys):
    png = tmp_path / "m.png"
    assert main(["sweep", "--model", "lps", "--grid", "voltage=40,80", "--t-end", "1e-4", "--no-progress",
                 "--metric", metric, "--plot", str(png)]) == 2
    err = capsys.readouterr().err
    assert f"--metric {metric} is defined for sawtooth trains only" in err and "triangle" in err
    assert not png.exists()


def test_t_end_past_a_sampled_input_warns_with_the_times(tmp_path, capsys):
    csv = tmp_path / "v.csv"
    csv.write_text("t,V\n0,0\n5e-4,40\n1e-3,40\n")
    warnings.simplefilter("default")  # as outside pytest (whose configuration makes warnings errors)
    assert main(["simulate", "--model", "lps", "--voltage-csv", str(csv), "--t-end", "2e-3"]) == 0
    err = capsys.readouterr().err
    assert "--t-end 0.002 s is past the last sample of --voltage-csv (t = 0.001 s): the input holds 40 V" in err
    assert main(["simulate", "--model", "lps", "--voltage-csv", str(csv)]) == 0
    assert "past the last sample" not in capsys.readouterr().err


def test_csv_has_the_reading_when_a_sensor_effect_is_on_and_titles_name_the_effects(tmp_path, capsys):
    plain, sensed = tmp_path / "plain.csv", tmp_path / "sensed.csv"
    base = ["simulate", "--model", "lps", "--t-end", "1e-3", "--save-every", "10"]
    assert main([*base, "--out", str(plain)]) == 0
    assert main([*base, "--effect", "tau_sensor=2e-5", "--out", str(sensed)]) == 0
    assert plain.read_text().splitlines()[0] == "t_s,voltage_V,x1_m,x2_m,friction_N,fh_N"
    assert sensed.read_text().splitlines()[0] == "t_s,voltage_V,x1_m,x2_m,friction_N,fh_N,reading_m"
    data = np.loadtxt(sensed, delimiter=",", skiprows=1)
    r = idm_rs.simulate(idm_rs.Params(), idm_rs.Triangle(), t_end=1e-3, model="lps", save_every=10,
                        effects=idm_rs.Effects(tau_sensor=2e-5))
    np.testing.assert_array_equal(data[:, 6], r.reading)
    assert np.abs(data[:, 6] - data[:, 2]).max() > 1e-8  # the low-passed reading lags x1
    assert "tau_sensor = 2e-05" in result_title(r)
    ds = idm_rs.sweep(idm_rs.Params(), idm_rs.Triangle(), {"voltage": [40.0, 80.0]}, t_end=1e-4, dt=1e-8,
                      model="lps", progress=False, effects=idm_rs.Effects(tau_sensor=2e-5))
    assert "effects: tau_sensor = 2e-05" in sweep_title(ds, "final_position")


def test_sweep_titles_fit_the_figure_and_results_print_a_summary():
    ds = idm_rs.sweep(idm_rs.Params(), idm_rs.Sawtooth(80.0, 500.0, 4), {"frequency": [400.0, 500.0]},
                      method="auto", model="dps", progress=False)
    title = sweep_title(ds, "mean_velocity")
    assert "frequency=swept" in title
    assert all(len(line) <= 95 for line in title.splitlines()), title
    r = idm_rs.simulate(idm_rs.Params(), idm_rs.Triangle(), t_end=1e-3, model="lps", save_every=1)
    text = repr(r)
    assert text.startswith("SimulationResult(LPS, Triangle(") and "100001 saved times" in text
    assert len(text) < 300 and "array(" not in text


def test_paper_output_is_ignored_and_the_help_is_current(capsys):
    ignored = (ROOT / ".gitignore").read_text().splitlines()
    assert "/idm-rs-paper/" in ignored and "/idm-rs-characteristics/" in ignored
    with pytest.raises(SystemExit):
        main(["--help"])
    top = capsys.readouterr().out
    assert "EMPS so far" not in top and "spring-slider" in top
    readme = (ROOT / "README.md").read_text()
    for command in ("reproduce", "simulate", "sweep", "characterize", "rig-fit", "diagnose"):
        assert f"`idm-rs {command}" in readme, command


def test_kernel_backends_never_return_train_metrics_as_silent_nan():
    saw = idm_rs.Sawtooth(80.0, 500.0, 3)
    kw = dict(t_end=6e-3, dt=5e-8, model="lps", progress=False, backend="kernel-cpu")
    ds = idm_rs.sweep(idm_rs.Params(), saw, {"voltage": [60.0, 80.0]}, **kw)
    assert (ds.status.values == 1).all()
    for m in ("mean_velocity", "step_mean", "backslip", "direction"):
        assert m not in ds
    assert "mean_velocity" in ds.attrs["metrics_not_computed"]
    assert np.isfinite(ds.step_per_cycle.values).all()
    with pytest.raises(ValueError, match=r"does not compute the steady-state metric\(s\) \['mean_velocity'\]"):
        idm_rs.sweep(idm_rs.Params(), saw, {"voltage": [60.0]}, metrics=["mean_velocity"], **kw)


def test_a_sweep_title_says_the_method_asked_and_each_points_own_end():
    """Before: a heat map titled "dopri5" under an `auto` command, and one t_end when each
    point ran to the end of its own train."""
    train = idm_rs.Sawtooth(amplitude=80.0, frequency=500.0, cycles=3, rise=1e-4)
    ds = idm_rs.sweep(idm_rs.Params(), train, {"frequency": [500.0, 1000.0]}, model="lps", method="auto",
                      progress=False)
    title = sweep_title(ds, "mean_velocity")
    assert title.split("\n", 1)[1].replace("\n", " ").count("auto (") == 1, title
    assert "each point to its own waveform's end" in title and "t_end =" not in title
