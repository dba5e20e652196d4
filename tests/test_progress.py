"""Progress that says what runs and how long it will take: characterize's bars name its own
curves (they said "idm-rs sweep"), a sweep's estimate is the whole run's average rate."""

from __future__ import annotations

import importlib

import idm_rs
from idm_rs.actuator import characterize


def test_characterize_names_its_curves_on_its_bars(capsys):
    characterize(idm_rs.Params(), model="lps", frequencies=[200.0, 500.0], voltages=[80.0], step_voltages=[60.0, 100.0],
                 frequency=200.0, cycles=3, skip_cycles=1, loads=3, progress=True)
    err = capsys.readouterr().err
    assert "characterize: velocity map" in err and "characterize: step curve" in err
    assert "idm-rs sweep" not in err


def test_a_sweep_bar_estimates_from_the_whole_run():
    bar = importlib.import_module("idm_rs.sweep")._progress_bar(10, "label")
    assert bar.smoothing == 0 and bar.desc == "label"
    bar.close()
