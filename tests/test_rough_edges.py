"""The rough edges a new user hit (issue 11), each with the behaviour it now has: clear refusals
naming the value, step hints that work, interruptible runs, per-point reasons, CLI effects and
measured voltages."""

from __future__ import annotations

import importlib
import re
import threading
import warnings

import numpy as np
import pytest

import idm_rs
from conftest import interrupt_main_when
from idm_rs.apps.cli import main
from idm_rs.apps.cli_figures import _waveform_title

P = idm_rs.Params()
W = idm_rs.Triangle()


# --- refusals that name the value ----------------------------------------------------------------


def test_massless_pe_with_a_multi_element_bar_names_the_parameter_and_the_fix(capsys):
    p = P.replace(pe_density=0.0)
    with pytest.raises(ValueError, match=r"'pe_density'.*'lps'.*n_elements = 1"):
        idm_rs.simulate(p, W, t_end=1e-4, model="dps", n_elements=4)
    idm_rs.simulate(p, W, t_end=1e-4, model="dps", n_elements=1)  # a massless bar of one element is fine
    with pytest.raises(ValueError, match="'pe_density'"):
        idm_rs.sweep(P, W, {"pe_density": [0.0, 8000.0]}, t_end=1e-4, model="dps", progress=False)
    assert main(["simulate", "--param", "pe_density=0", "--t-end", "1e-4"]) == 2
    assert "'pe_density'" in capsys.readouterr().err


@pytest.mark.parametrize("bad", [dict(m1=True), dict(mu_k=np.bool_(False))])
def test_booleans_are_not_parameters(bad):
    with pytest.raises(TypeError, match=next(iter(bad))):
        idm_rs.Params(**bad)
    with pytest.raises(TypeError, match="k_ground"):
        idm_rs.Effects(k_ground=True)  # type: ignore[arg-type]


def test_two_dimensional_inputs_are_refused():
    with pytest.raises(ValueError, match="'t' must be 1-D"):
        idm_rs.Sampled(np.zeros((2, 3)), np.zeros(6))
    with pytest.raises(ValueError, match="'voltage' must be 1-D"):
        idm_rs.sweep(P, W, {"voltage": np.ones((2, 2))}, t_end=1e-4, progress=False)


def test_static_below_kinetic_friction_warns_with_the_values():
    with pytest.warns(RuntimeWarning, match=r"mu_s = 0.4 is below mu_k = 0.5"):
        idm_rs.Params(mu_s=0.4, mu_k=0.5)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        idm_rs.Params(mu_s=0.5, mu_k=0.5)  # equal: no Stribeck peak, no warning


@pytest.mark.parametrize("argv, needle", [
    (["simulate", "--cycles", "4"], "--cycles applies to --waveform sawtooth"),
    (["simulate", "--waveform", "sawtooth", "--fall", "1e-3"], "--fall applies to the triangle"),
    (["simulate", "--effect", "nosuch=1"], "unknown effect parameter 'nosuch'"),
])
def test_options_that_do_not_apply_are_refused(argv, needle, capsys):
    assert main(argv) == 2
    assert needle in capsys.readouterr().err


def test_invalid_sweep_points_keep_their_reason():
    ds = idm_rs.sweep(P, idm_rs.Sawtooth(cycles=2, frequency=1000.0, rise=1e-4), {"cycles": [1.5, 2.0]}, t_end=2e-3,
                      model="lps", method="auto", skip_cycles=1, progress=False)
    assert ds.status.values.tolist() == [4, 1]
    assert "'cycles'" in ds.reason.values[0] and "1.5" in ds.reason.values[0]
    assert ds.reason.values[1] == ""


def test_diverged_points_say_when_and_at_what_step():
    ds = idm_rs.sweep(P, W, {"voltage": [120.0]}, t_end=2e-3, dt=1e-6, model="lps", retries=1, progress=False)
    assert ds.status.values[0] == 3
    assert re.search(r"diverged at t = \S+ s at every step tried \(down to dt = 5e-7 s\)", ds.reason.values[0])


# --- step hints ----------------------------------------------------------------------------------


def test_divergence_hint_is_a_step_that_works():
    """The issue: dt = 2.5e-6 suggested 6.3e-10 s although 1e-7 works."""
    with pytest.raises(idm_rs.DivergenceError) as e:
        idm_rs.simulate(P, W, t_end=10e-3, dt=2.5e-6, model="lps")
    hint = float(re.search(r"try dt = (\S+) s", str(e.value)).group(1))
    assert 2.5e-6 / 64 <= hint < 2.5e-6
    r = idm_rs.simulate(P, W, t_end=10e-3, dt=hint, model="lps", save_every=10_000)
    assert r.complete and abs(r.final_position - 1.678e-6) < 5e-9


def test_a_step_that_does_not_divide_gets_one_that_does():
    with pytest.raises(ValueError, match=r"breakpoint at t = 5e-4 s .*end of a rise.*dt = (\S+) s divides") as e:
        idm_rs.simulate(P, W, t_end=10e-3, dt=3e-8, model="lps")
    hint = float(re.search(r"dt = (\S+) s divides", str(e.value)).group(1))
    assert hint == 2.5e-8  # the largest round step below 3e-8 that fits
    idm_rs.simulate(P, W, t_end=1e-3, dt=hint, model="lps")  # accepted by the step plan
    with pytest.raises(ValueError, match=r"does not divide t_end = .* into whole steps; dt = \S+ s divides"):
        idm_rs.simulate(P, W, t_end=10e-3 + 1e-8, dt=2e-8, model="lps")


# --- interrupting simulate -----------------------------------------------------------------------


def test_ctrl_c_stops_simulate_and_keeps_the_trajectory_so_far(monkeypatch):
    # Ctrl-C 0.5 s after the engine call began (not after a fixed time: see interrupt_main_when)
    started = threading.Event()
    engine = importlib.import_module("idm_rs.core.simulation").engine
    engine_simulate = engine.simulate

    def simulate(*args):
        started.set()
        return engine_simulate(*args)

    monkeypatch.setattr(engine, "simulate", simulate)
    interrupter = interrupt_main_when(started.is_set, delay=0.5)
    with pytest.warns(RuntimeWarning, match="take minutes"):  # 2e8 steps: warned before the run
        with pytest.raises(KeyboardInterrupt, match="simulate interrupted at t = ") as stop:
            idm_rs.simulate(P, W, t_end=2.0, dt=1e-8, model="lps", save_every=100_000)
    interrupter.join()
    r = idm_rs.partial_result(stop.value)
    assert not r.complete
    assert 0 < r.t[-1] < 2.0 and r.final_position == r.main_body[-1]


# --- the CLI: effects and measured voltages ------------------------------------------------------


def test_cli_sets_an_effect_and_drives_with_a_measured_voltage(tmp_path, capsys):
    csv = tmp_path / "v.csv"
    t = np.array([0.0, 0.5e-3, 2e-3])
    np.savetxt(csv, np.column_stack([t, [0.0, 80.0, 0.0]]), delimiter=",", header="t,voltage", comments="")
    out = tmp_path / "r.csv"
    assert main(["simulate", "--model", "lps", "--voltage-csv", str(csv), "--t-end", "2e-3",
                 "--effect", "k_ground=2000", "--out", str(out)]) == 0
    x_cli = np.loadtxt(out, delimiter=",", skiprows=1)[-1, 2]
    r = idm_rs.simulate(P, idm_rs.Sampled(t, [0.0, 80.0, 0.0]), t_end=2e-3, model="lps",
                        effects=idm_rs.Effects(k_ground=2000.0))
    assert x_cli == r.final_position


# --- figures -------------------------------------------------------------------------------------


def test_heat_map_title_shows_swept_fields_as_swept():
    text = "Triangle(amplitude=80.0, rise=0.0005, fall=0.0095, delay=0.0)"
    swept = "Triangle(amplitude=swept, rise=0.0005, fall=0.0095, delay=0.0)"
    assert _waveform_title(text, ["mass_ratio", "voltage"]) == swept
    assert "rise=swept" in _waveform_title(text, ["rise"])


def test_fit_plots_align_models_on_the_rest_before_the_drive():
    """The nominal model was drawn ~1 µm off before the drive: aligned by its mean over the
    whole record, a model that drifts away later was shifted half way to meet the data."""
    from idm_rs.diagnosis.plots import _aligned, _rest_before_drive

    t = np.linspace(0.0, 10e-3, 1001)
    voltage = np.where(t < 1e-3, 0.0, 80.0)
    data = 5e-6 + np.where(t < 1e-3, 0.0, 1e6 * (t - 1e-3) ** 2)  # sensor offset 5 µm, then motion
    model = np.where(t < 1e-3, 0.0, 3e6 * (t - 1e-3) ** 2)  # moves 3x too far
    aligned, off = _aligned(data, model, _rest_before_drive(voltage))
    assert off == pytest.approx(5e-6)
    assert np.abs(aligned - data)[t < 1e-3].max() < 1e-18
    _, off_all = _aligned(data, model)  # without the rest: the old, misleading alignment
    assert abs(off_all - 5e-6) > 1e-5


def test_sawtooth_friction_panel_zooms_on_one_cycle(tmp_path):
    from idm_rs.apps.cli import plot_result

    r = idm_rs.simulate(P, idm_rs.Sawtooth(cycles=5, frequency=1000.0, rise=1e-4), t_end=5e-3, model="lps",
                        method="auto", save_every=1)
    plot_result(r, tmp_path / "saw.png")
    assert (tmp_path / "saw.png").stat().st_size > 20_000
