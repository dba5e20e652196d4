"""Figures that show what the text says: the simulate figure draws every state the dynamics
need (no aliasing by --save-every), its legend sits off the traces, and the CSV still holds
the --save-every states."""

import importlib

import numpy as np

import idm_rs
from idm_rs.apps.cli import main


def test_simulate_plot_draws_every_accepted_step_and_the_csv_every_save_every_th(tmp_path, monkeypatch):
    cli = importlib.import_module("idm_rs.apps.cli")
    drawn = {}
    real = cli.plot_result
    monkeypatch.setattr(cli, "plot_result", lambda r, p: drawn.setdefault("fig", real(r, p)))
    out = tmp_path / "r.csv"
    assert main(["simulate", "--model", "lps", "--method", "auto", "--waveform", "sawtooth", "--cycles", "4",
                 "--plot", str(tmp_path / "r.png"), "--out", str(out)]) == 0
    w = idm_rs.Sawtooth(80.0, 100.0, 4)
    every = idm_rs.simulate(idm_rs.Params(), w, t_end=w.duration, model="lps", method="auto", save_every=1)
    fig = drawn["fig"]
    friction = fig.axes[1].get_lines()[0]  # the last cycle's friction
    per_cycle = int(np.count_nonzero((every.t >= 0.03 - 1e-12) & (every.t <= 0.04 + 1e-12)))
    assert friction.get_xdata().size == per_cycle > 2_000  # every accepted step of the cycle, not every 100th
    rows = np.loadtxt(out, delimiter=",", skiprows=1)
    thin = idm_rs.simulate(idm_rs.Params(), w, t_end=w.duration, model="lps", method="auto", save_every=100)
    np.testing.assert_array_equal(rows[:, 0], thin.t)
    legend = fig.axes[0].get_legend()
    assert legend.get_bbox_to_anchor().y0 >= fig.axes[0].get_window_extent().y1 - 1  # above the axes
