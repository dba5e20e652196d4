"""The ``idm-rs`` command line (``python -m idm_rs``): reproduce, simulate, errors."""

from __future__ import annotations

import subprocess
import sys

import numpy as np
import pytest

import idm_rs
from idm_rs import paper
from idm_rs.cli import main, paper_case_csv, parse_param_overrides

PNG_MAGIC = b"\x89PNG\r\n\x1a\n"
FIGURES = [f"fig6{c}.png" for c in "abcd"] + [f"fig7{c}.png" for c in "abcd"]


def test_reproduce_quick_writes_figures_and_table(tmp_path, capsys):
    out = tmp_path / "paper"
    assert main(["reproduce", "--quick", "--out", str(out), "--no-progress"]) == 0
    for name in FIGURES:
        data = (out / name).read_bytes()
        assert data.startswith(PNG_MAGIC), name
        assert len(data) > 20_000, f"{name} looks empty"
    assert (out / "paper_case.csv").stat().st_size > 0
    text = capsys.readouterr().out
    assert "2.413" in text and "2.459" in text  # the paper's values
    assert "1.678" in text and "1.711" in text  # MODEL.md's reference (and ours)
    lps, dps = paper.run_paper_case(dt=2e-8, save_every=50_000)
    assert f"{lps.final_position * 1e6:.3f}" in text
    assert f"{dps.final_position * 1e6:.3f}" in text
    assert "+33" in text and "+46" in text  # the DPS - LPS gap, ours and the paper's
    assert "does not reproduce" in text


def test_paper_case_csv_columns(tmp_path):
    lps, dps = paper.run_paper_case(dt=2e-8, save_every=100)
    path = tmp_path / "pc.csv"
    paper_case_csv(lps, dps, path, every=3)
    data = np.genfromtxt(path, delimiter=",", names=True)
    assert data.dtype.names[:4] == ("t", "voltage", "x1_lps", "x2_lps")
    assert data["t"][-1] == pytest.approx(10e-3)
    assert data["x1_lps"][-1] == lps.final_position
    assert data["x1_dps"][-1] == dps.final_position


def test_simulate_csv_matches_api(tmp_path, capsys):
    csv = tmp_path / "run.csv"
    argv = [
        "simulate", "--model", "lps", "--dt", "2e-8", "--rise", "1e-3", "--fall", "4e-3",
        "--t-end", "6e-3", "--param", "m2=0.4", "mu_k=0.45", "--out", str(csv),
    ]
    assert main(argv) == 0
    data = np.genfromtxt(csv, delimiter=",", names=True)
    assert data.dtype.names == ("t", "voltage", "x1", "x2", "friction", "fh")
    ref = idm_rs.simulate(
        idm_rs.Params(m2=0.4, mu_k=0.45), idm_rs.Triangle(80.0, 1e-3, 4e-3), t_end=6e-3, dt=2e-8, model="lps"
    )
    assert data["x1"][-1] == ref.final_position
    np.testing.assert_array_equal(data["x1"], ref.main_body)
    np.testing.assert_array_equal(data["voltage"], ref.voltage)
    text = capsys.readouterr().out
    assert f"{ref.final_position * 1e6:.6f} µm" in text
    assert "run time" in text


def test_simulate_netcdf_and_plot(tmp_path):
    xr = pytest.importorskip("xarray")
    nc, png = tmp_path / "run.nc", tmp_path / "run.png"
    argv = [
        "simulate", "--dt", "2e-8", "--waveform", "sawtooth", "--frequency", "500", "--cycles", "2",
        "--direction", "backward", "--no-hysteresis", "--out", str(nc), "--plot", str(png),
    ]
    assert main(argv) == 0
    ref = idm_rs.simulate(
        idm_rs.Params(), idm_rs.Sawtooth(80.0, 500.0, 2, direction="backward"), t_end=4e-3, dt=2e-8,
        piezo_hysteresis=False,
    )
    with xr.open_dataset(nc) as ds:
        assert float(ds["main_body"][-1]) == ref.final_position
        assert ds.attrs["model"] == "dps"
    assert png.read_bytes().startswith(PNG_MAGIC)


def test_bad_param_exits_2_naming_it(capsys):
    assert main(["simulate", "--param", "m1=-1"]) == 2
    err = capsys.readouterr().err
    assert err.startswith("error: ") and "'m1'" in err
    assert err.count("\n") == 1 and "Traceback" not in err


@pytest.mark.parametrize(
    "argv, needle",
    [
        (["simulate", "--param", "nosuch=1"], "nosuch"),
        (["simulate", "--param", "m2=abc"], "m2"),
        (["simulate", "--param", "m2"], "NAME=VALUE"),
        (["simulate", "--dt", "3e-8"], "does not divide"),
        (["simulate", "--dt", "5e-7", "--t-end", "1e-3"], "diverged"),
        (["simulate", "--out", "x.txt"], ".txt"),
    ],
)
def test_errors_are_one_line(argv, needle, capsys):
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert err.startswith("error: ") and needle in err and err.count("\n") == 1


def test_parse_param_overrides():
    assert parse_param_overrides(["m1=0.5", "normal_force=auto"]) == {"m1": 0.5, "normal_force": None}


def test_python_m_entry_point():
    run = subprocess.run(
        [sys.executable, "-m", "idm_rs", "simulate", "--param", "m1=-1"], capture_output=True, text=True
    )
    assert run.returncode == 2
    assert run.stderr.startswith("error: ") and "m1" in run.stderr and "Traceback" not in run.stderr
    run = subprocess.run([sys.executable, "-m", "idm_rs", "--version"], capture_output=True, text=True)
    assert run.returncode == 0 and idm_rs.__version__ in run.stdout
