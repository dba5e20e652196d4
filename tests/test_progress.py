"""Progress that says what runs and how long it will take: characterize's bars name its own
curves (they said "idm-rs sweep"), a sweep's estimate is the whole run's average rate."""

from __future__ import annotations

import importlib

import idm_rs
from idm_rs.apps.actuator import characterize


def test_characterize_names_its_curves_on_its_bars(capsys):
    characterize(idm_rs.Params(), model="lps", frequencies=[200.0, 500.0], voltages=[80.0], step_voltages=[60.0, 100.0],
                 frequency=200.0, cycles=3, skip_cycles=1, loads=3, progress=True)
    err = capsys.readouterr().err
    assert "characterize: velocity map" in err and "characterize: step curve" in err
    assert "idm-rs sweep" not in err


def test_a_sweep_bar_estimates_from_the_whole_run():
    bar = importlib.import_module("idm_rs.sweeps.sweep")._progress_bar(10, "label")
    assert bar.smoothing == 0 and bar.desc == "label"
    bar.close()


def test_a_long_simulate_shows_progress_and_gives_the_same_result(capsys):
    """`simulate` had no progress for 1e8 steps: with progress=True an RK4 run goes in pieces on
    its save grid, each continued from the last one's state, bit for bit the one-piece result."""
    import numpy as np

    p = idm_rs.Params()
    w = idm_rs.Triangle(amplitude=80.0, rise=0.5e-3, fall=9.5e-3)
    one = idm_rs.simulate(p, w, t_end=10e-3, dt=1e-8, model="lps", save_every=7)
    pieces = idm_rs.simulate(p, w, t_end=10e-3, dt=1e-8, model="lps", save_every=7, progress=True)
    assert "idm-rs simulate" in capsys.readouterr().err
    for name in ("t", "nodes", "velocities", "friction", "fh", "voltage", "reading"):
        assert np.array_equal(getattr(one, name), getattr(pieces, name)), name
    assert one.final_position == pieces.final_position and np.array_equal(one.final_state, pieces.final_state)
