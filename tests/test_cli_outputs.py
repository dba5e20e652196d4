"""Output paths are checked before a command runs: a type it cannot write, a place nothing can
be written to, a folder given for a file (or the reverse) is refused with exit 2 and the option
named — before any simulation, so no minutes are lost and nothing is half written."""

from __future__ import annotations

import importlib

import pytest

from idm_rs.apps.cli import main


@pytest.fixture
def nothing_runs(monkeypatch):
    """Fail the test if a command starts simulating."""
    def refuse(*args, **kwargs):
        raise AssertionError("the command ran before checking its outputs")

    for module, name in (("idm_rs.core.simulation", "simulate"), ("idm_rs.sweeps.sweep", "sweep"),
                         ("idm_rs.apps.actuator", "characterize"), ("idm_rs.apps.paper", "run_paper_case"),
                         ("idm_rs.diagnosis", "diagnose")):
        monkeypatch.setattr(importlib.import_module(module), name, refuse)
    monkeypatch.setattr(importlib.import_module("idm_rs.apps.cli"), "simulate", refuse)


@pytest.mark.parametrize("argv, words", [
    (["simulate", "--out", "/proc/run.csv"], "--out: cannot write '/proc/run.csv'"),
    (["simulate", "--plot", "run.txt"], "--plot: unknown file type '.txt' in 'run.txt' (use .png, .pdf, .svg)"),
    (["simulate", "--out", "run.json"], "--out: unknown file type '.json'"),
    (["sweep", "--grid", "voltage=60,80", "--out", "s.csv"],
     "--out: unknown file type '.csv' in 's.csv' (use .nc, .zarr)"),
    (["sweep", "--grid", "voltage=60,80", "--out", "/proc/s.zarr"], "--out: cannot write '/proc/s.zarr'"),
    (["sweep", "--grid", "voltage=60,80", "--plot", "s.pdf"], "--plot: unknown file type '.pdf'"),
    (["reproduce", "--out", "/proc/figs"], "--out: cannot write '/proc/figs'"),
    (["characterize", "--out", "/proc/ch"], "--out: cannot write '/proc/ch'"),
])
def test_a_bad_output_is_refused_before_the_run(argv, words, capsys, nothing_runs, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    assert main(argv) == 2
    assert words in capsys.readouterr().err


def test_a_file_for_a_folder_and_a_folder_for_a_file(capsys, nothing_runs, tmp_path):
    a_file = tmp_path / "x.png"
    a_file.write_text("")
    assert main(["diagnose", str(tmp_path), "--plots", str(a_file)]) == 2
    assert "--plots: " in capsys.readouterr().err
    folder = tmp_path / "r.csv"
    folder.mkdir()
    assert main(["simulate", "--out", str(folder)]) == 2
    assert "is a folder; name a file" in capsys.readouterr().err
    assert not list(tmp_path.glob(".idm-rs-probe-*"))  # the probe leaves nothing behind
