"""No legend covers data: every figure the CLI writes is checked by drawing it and testing
that no plotted point falls inside a legend's box (display coordinates)."""

from pathlib import Path

import matplotlib
import numpy as np
import pytest

import idm_rs
from idm_rs.apps.cli import main

matplotlib.use("Agg")
REAL = Path(__file__).resolve().parents[2] / "shared" / "realdata"


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
                if line.get_linestyle() not in ("None", "", " ") and len(d) > 1:
                    # a drawn segment can cross the box with both its ends outside: sample it
                    f = np.linspace(0.0, 1.0, 25)[:, None, None]
                    d = (d[:-1] + f * (d[1:] - d[:-1])).reshape(-1, 2)
                # a marker covers its size around its point: half of it may reach into the box
                pad = 0.5 * line.get_markersize() * fig.dpi / 72 if line.get_marker() not in (None, "None", "") else 0
                inside = ((d[:, 0] > box.x0 - pad) & (d[:, 0] < box.x1 + pad) & (d[:, 1] > box.y0 - pad)
                          & (d[:, 1] < box.y1 + pad))
                in_axes = ((d[:, 0] >= ax.bbox.x0) & (d[:, 0] <= ax.bbox.x1) & (d[:, 1] >= ax.bbox.y0)
                           & (d[:, 1] <= ax.bbox.y1))
                if np.any(inside & in_axes):
                    bad.append(f"{ax_l.get_title() or ax_l.get_ylabel()}: {line.get_label()}")
            for patch in (p for c in ax.containers for p in getattr(c, "patches", [])):  # bars, not shaded spans
                extent = patch.get_window_extent(renderer)
                if extent.width * extent.height > 0 and extent.overlaps(box) and ax.bbox.overlaps(extent):
                    bad.append(f"{ax_l.get_title() or ax_l.get_ylabel()}: a bar")
            for text in ax.texts:  # the numbers written beside the bars
                if text.get_text() and text.get_window_extent(renderer).overlaps(box):
                    bad.append(f"{ax_l.get_title() or ax_l.get_ylabel()}: text {text.get_text()!r}")
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


@pytest.mark.parametrize("quick", [False, True])
@pytest.mark.parametrize("key", ["7a", "7b", "7c", "7d"])
def test_fig7_legends_sit_off_the_data(tmp_path, saved, key, quick):
    """Fig. 7c's legends covered its curves. Drawn from the full Fig. 7 values (adaptive runs,
    which draw the same curves within the figure's resolution)."""
    from idm_rs.apps import paper
    from idm_rs.apps.figures import fig7

    sweep = next(s for s in paper.fig7_sweeps(quick=quick) if s.key == key)
    runs = []
    for v in sweep.values:
        case = sweep.build(v)
        r = idm_rs.simulate(case.params, case.waveform, t_end=paper.PAPER_T_END, model=case.model,
                            n_elements=case.n_elements, method="auto", save_every=20)
        runs.append(paper.SweepRun(v, r, 1e-8))
    dense = paper.run_dense(sweep, dt=2e-8, method="auto")
    fig7(sweep, runs, tmp_path / f"fig{key}.png", dense=dense)
    assert _covered(saved[-1]) == []
