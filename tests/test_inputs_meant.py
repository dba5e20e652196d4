"""Inputs that are probably not meant are said by name, and wrong types get a clear error
instead of one from deep inside: a sampled drive that steps at t = 0, a start time without a
start state, tolerances given to RK4, an element count for the LPS in the CLI, a voltage file in
milliseconds, no waveform, a time given as text."""

from __future__ import annotations

import warnings

import numpy as np
import pytest

import idm_rs
from idm_rs.apps.cli import main

P = idm_rs.Params()
W = idm_rs.Triangle(amplitude=80.0, rise=0.5e-3, fall=0.5e-3)


def test_a_sampled_drive_that_steps_at_t0_is_said():
    with pytest.warns(UserWarning, match=r"first sample is at t = 0.001 s with 50 V .* a voltage step at t = 0"):
        idm_rs.Sampled([1e-3, 2e-3], [50.0, 0.0])
    idm_rs.Sampled([0.0, 2e-3], [50.0, 0.0])  # from t = 0: nothing to say (an error if warned)
    idm_rs.Sampled([1e-3, 2e-3], [0.0, 50.0])


def test_a_start_time_without_a_start_state_is_said():
    with pytest.warns(UserWarning, match=r"t_start = 0.0005 s without an initial_state: .* already at 80 V"):
        idm_rs.simulate(P, W, t_end=6e-4, t_start=5e-4, model="lps")


def test_tolerances_given_to_rk4_are_said_to_be_ignored():
    with pytest.warns(UserWarning, match="rtol are for the adaptive methods"):
        idm_rs.simulate(P, W, t_end=1e-4, model="lps", method="rk4", rtol=1e-9)


def test_no_waveform_and_a_time_as_text_get_clear_errors():
    with pytest.raises(TypeError, match=r"waveform must be an idm_rs waveform .* got None"):
        idm_rs.simulate(P, None, t_end=1e-3)  # type: ignore[arg-type]
    with pytest.raises(TypeError, match=r"parameter 't_end' must be a time in seconds \(a number\), got '10e-3'"):
        idm_rs.simulate(P, W, t_end="10e-3")  # type: ignore[arg-type]
    with pytest.raises(ValueError, match=r"parameter 't_end' must be a positive, finite time"):
        idm_rs.simulate(P, W, t_end=float("nan"))


def test_the_cli_says_the_lps_ignores_an_element_count(capsys, tmp_path):
    with warnings.catch_warnings():
        warnings.simplefilter("default")  # as outside pytest: the CLI prints them as one line
        assert main(["simulate", "--model", "lps", "--n-elements", "8", "--t-end", "1e-4", "--method", "auto"]) == 0
    assert "--n-elements 8 is for --model dps" in capsys.readouterr().err


def test_a_voltage_file_in_milliseconds_is_said(capsys, tmp_path):
    csv = tmp_path / "v.csv"
    np.savetxt(csv, np.column_stack([[0.0, 0.5, 4000.0], [0.0, 80.0, 0.0]]), delimiter=",", header="t,voltage",
               comments="")
    with warnings.catch_warnings():
        warnings.simplefilter("default")
        assert main(["simulate", "--model", "lps", "--voltage-csv", str(csv), "--t-end", "1e-4", "--method",
                     "auto"]) == 0
    assert "the times run to 4000 s (read in seconds)" in capsys.readouterr().err
