"""No legend covers data: every figure the CLI writes is checked by drawing it and testing
that no plotted point falls inside a legend's box (display coordinates)."""

from pathlib import Path

import matplotlib
import numpy as np
import pytest

from idm_rs.cli import main

matplotlib.use("Agg")
REAL = Path(__file__).resolve().parents[2] / "shared" / "realdata"


@pytest.fixture
def saved(monkeypatch):
    """Every figure saved while the test runs, drawn."""
    from matplotlib.figure import Figure

    figs = []
    real = Figure.savefig

    def keep(self, *args, **kwargs):
        out = real(self, *args, **kwargs)
        figs.append(self)
        return out

    monkeypatch.setattr(Figure, "savefig", keep)
    return figs


def _covered(fig) -> list[str]:
    """Axes whose legend box holds a plotted point."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg

    canvas = FigureCanvasAgg(fig)  # a closed figure has lost its canvas
    canvas.draw()
    bad = []
    renderer = canvas.get_renderer()
    legends = [(ax, ax.get_legend()) for ax in fig.axes if ax.get_legend() is not None]
    for ax_l, legend in legends:
        box = legend.get_window_extent(renderer)
        for ax in fig.axes:  # a twin axes' lines lie under the other's legend too
            if not ax.bbox.overlaps(box):
                continue
            for line in ax.get_lines():
                xy = np.column_stack(line.get_data()).astype(float)
                xy = xy[np.isfinite(xy).all(axis=1)]
                if xy.size == 0:
                    continue
                d = ax.transData.transform(xy)
                inside = ((d[:, 0] > box.x0) & (d[:, 0] < box.x1) & (d[:, 1] > box.y0) & (d[:, 1] < box.y1))
                in_axes = ((d[:, 0] >= ax.bbox.x0) & (d[:, 0] <= ax.bbox.x1) & (d[:, 1] >= ax.bbox.y0)
                           & (d[:, 1] <= ax.bbox.y1))
                if np.any(inside & in_axes):
                    bad.append(f"{ax_l.get_title() or ax_l.get_ylabel()}: {line.get_label()}")
    return bad


def test_simulate_and_characterize_legends_sit_off_the_data(tmp_path, saved, capsys):
    assert main(["simulate", "--model", "lps", "--method", "auto", "--waveform", "sawtooth", "--cycles", "4",
                 "--plot", str(tmp_path / "s.png")]) == 0
    assert main(["characterize", "--model", "lps", "--out", str(tmp_path / "c"), "--no-progress", "--cycles", "4",
                 "--frequencies", "50,200,800", "--voltages", "40,80,120", "--step-voltages", "20:120:6",
                 "--loads", "5"]) == 0
    assert len(saved) == 4
    assert "steady state: the cycles after the first 2 of 4 (--skip-cycles)" in capsys.readouterr().out
    for fig in saved:
        assert _covered(fig) == [], fig


@pytest.mark.skipif(not REAL.exists(), reason="the measured data sets are not here")
@pytest.mark.parametrize("record", ["marino_frame_friction/s_b_450g_x.mat", "ensl_paper_stickslip/k1002Nm_v42.mat"])
def test_rig_diagnosis_legends_sit_off_the_data(tmp_path, saved, record):
    assert main(["diagnose", str(REAL / record), "--plots", str(tmp_path)]) == 0
    assert saved
    for fig in saved:
        assert _covered(fig) == [], fig


@pytest.mark.skipif(not REAL.exists(), reason="the measured data sets are not here")
def test_a_drift_is_drawn_against_the_time_of_the_record_not_the_stick_time(tmp_path, saved):
    """k1002Nm_v42: the onset force drifts over the record; against the stick time the drift
    model would be a scribble, so there the onset forces are shown with the drift removed."""
    assert main(["diagnose", str(REAL / "ensl_paper_stickslip" / "k1002Nm_v42.mat"), "--plots", str(tmp_path)]) == 0
    fig = next(f for f in saved if any(ax.get_xlabel() == "stick time before the slip [s]" for ax in f.axes))
    stick = next(ax for ax in fig.axes if ax.get_xlabel() == "stick time before the slip [s]")
    assert all(line.get_linestyle() == "None" for line in stick.get_lines())  # markers only
    assert any("less the drift over record" in line.get_label() for line in stick.get_lines())
    when = next(ax for ax in fig.axes if ax.get_xlabel() == "time of the slip [s]")
    model = next(line for line in when.get_lines() if line.get_label() == "drift_over_record")
    assert np.all(np.diff(model.get_xdata()) >= 0)  # drawn in time order: a line, not a scribble
