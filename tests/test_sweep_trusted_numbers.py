"""Sweep numbers a user can take at first sight: every point runs its whole train, one
definition of the steady state shared with ``characterize``, throughput over the points that
finished, and the tolerances a user gives honoured by ``method="auto"``."""

import inspect

import numpy as np
import pytest
import xarray as xr

import idm_rs
from idm_rs import methods
from idm_rs.apps import actuator
from idm_rs.apps.cli_files import sweep_summary
from idm_rs.core.waveforms import STARTUP_CYCLES, Sawtooth

TRAIN = Sawtooth(80.0, 100.0, 4)


def test_each_point_runs_its_own_whole_train():
    """50 Hz needs 0.08 s for its 4 cycles, 100 Hz 0.04 s: each point gets its own end, and its
    steady state is the single run's, bit for bit."""
    ds = idm_rs.sweep(idm_rs.Params(), TRAIN, {"frequency": [50.0, 100.0]}, model="lps", method="auto",
                      progress=False, metrics=["step_mean", "mean_velocity"])
    assert "each point to its own waveform's end (0.04-0.08 s)" == ds.attrs["t_end_rule"]
    for f in (50.0, 100.0):
        alone = actuator.steady_state(idm_rs.Params(), Sawtooth(80.0, f, 4), model="lps")
        assert ds["step_mean"].sel(frequency=f).item() == alone.step_mean
        assert ds["mean_velocity"].sel(frequency=f).item() == alone.mean_velocity
    # a step of the 50 Hz train is not the 100 Hz one's: the test tells the trains apart
    assert abs(ds["step_mean"].sel(frequency=50.0).item() - ds["step_mean"].sel(frequency=100.0).item()) > 1e-8


def test_a_t_end_that_cuts_a_train_short_is_refused_with_the_point_and_the_fix():
    with pytest.raises(ValueError, match=r"frequency = 50 \(it ends at 0.08 s\).*t_end >= 0.08 s"):
        idm_rs.sweep(idm_rs.Params(), TRAIN, {"frequency": [50.0, 100.0]}, t_end=0.04, model="lps",
                     method="auto", progress=False)
    with pytest.raises(ValueError, match=r"cycles = 8"):
        idm_rs.sweep(idm_rs.Params(), TRAIN, {"cycles": [2, 8]}, t_end=0.05, model="lps", method="auto",
                     skip_cycles=1, progress=False)
    # long enough is run as given: the shorter train rests after its end
    ds = idm_rs.sweep(idm_rs.Params(), TRAIN, {"frequency": [100.0]}, t_end=0.05, model="lps", method="auto",
                      progress=False, metrics=["step_mean"])
    assert ds.attrs["t_end_rule"] == "as given" and ds.attrs["t_end_s"] == 0.05


def test_the_kernel_backend_refuses_trains_of_different_lengths_by_name():
    with pytest.raises(ValueError, match=r"one t_end.*give t_end=0.08"):
        idm_rs.sweep(idm_rs.Params(), TRAIN, {"frequency": [50.0, 100.0]}, model="lps", method="rk4",
                     backend="kernel-cpu", progress=False)


def test_one_definition_of_the_steady_state_in_sweep_and_characterize():
    for f in (idm_rs.sweep, actuator.steady_state, actuator.stall_force, actuator.characterize):
        assert inspect.signature(f).parameters["skip_cycles"].default == STARTUP_CYCLES == 2
    ch = actuator.characterize(model="lps", frequencies=[100.0], voltages=[80.0], step_voltages=[80.0],
                               cycles=4, loads=5, progress=False)
    sw = idm_rs.sweep(idm_rs.Params(), TRAIN, {"voltage": [80.0], "frequency": [100.0]}, model="lps",
                      method="auto", progress=False)
    assert sw.attrs["skip_cycles"] == ch.attrs["skip_cycles"] == 2
    for m in ("mean_velocity", "step_mean", "backslip"):
        assert ch[m].item() == sw[m].item()


def _summary_of(finished: int, points: int, wall: float) -> str:
    status = np.zeros(points, dtype=np.uint8)
    status[:finished] = 1
    ds = xr.Dataset({"status": (("m2",), status)}, coords={"m2": np.linspace(0.1, 0.2, points)})
    ds.attrs.update(points=points, points_finished=finished, wall_time_s=wall, model="lps", n_elements=1,
                    method="rk4", dt_s=1e-8, t_end_s=0.01, t_end_rule="as given", executor="local", complete=0)
    return sweep_summary(ds, "final_position")


def test_throughput_counts_the_points_that_finished():
    assert "15.2 points/s (152 of 4096 points)" in _summary_of(152, 4096, 10.0)
    text = _summary_of(0, 4096, 10.0)
    assert "no point finished" in text and "points/s" not in text


def test_auto_honours_the_tolerances_a_user_gives():
    assert methods.resolve("auto") == ("auto", 3e-7, 3e-7)
    assert methods.resolve("auto", 1e-9, None) == ("auto", 1e-9, 3e-7)
    assert methods.resolve("dopri5") == ("dopri5", 1e-7, 1e-7)
    with pytest.raises(ValueError, match="'rtol' must be a positive number"):
        methods.resolve("auto", -1.0)
    w = Sawtooth(80.0, 100.0, 2)
    loose = idm_rs.simulate(idm_rs.Params(), w, t_end=w.duration, model="lps", method="auto")
    tight = idm_rs.simulate(idm_rs.Params(), w, t_end=w.duration, model="lps", method="auto", rtol=1e-9, atol=1e-9)
    assert (loose.rtol, tight.rtol) == (3e-7, 1e-9)
    assert tight.t.size > 1.5 * loose.t.size  # the tighter tolerance takes more steps
    ds = idm_rs.sweep(idm_rs.Params(), w, {"voltage": [80.0]}, model="lps", method="auto", rtol=1e-9, atol=1e-9,
                      progress=False, metrics=["final_position"])
    assert ds.attrs["rtol"] == 1e-9 and ds["final_position"].item() == tight.final_position
