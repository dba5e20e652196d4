"""Continuing a run from a saved state (``t_start`` + ``initial_state``) through the Python API.

The claim (``simulate``'s docstring): with RK4 and a ``t_start`` on the step grid, a run to
``t_a`` followed by a run from ``t_a`` started from its ``final_state`` is the uninterrupted run,
bit for bit: the state carries everything the integrator needs (presliding force, asperity
deformation, piezo hysteresis, effect states, energy accounting). LPS runs of the paper case
take ~0.15 s per 10 ms at dt = 1e-8 s; the DPS runs are kept to 2 ms.
"""

from __future__ import annotations

import numpy as np
import pytest

import idm_rs

P = idm_rs.Params()
PAPER_WAVE = idm_rs.Triangle(80.0, 0.5e-3, 9.5e-3)
SHORT_WAVE = idm_rs.Triangle(80.0, 0.3e-3, 0.7e-3)  # up and back down within 1 ms


def _split(t_a: float, t_end: float, **kw) -> tuple[idm_rs.SimulationResult, idm_rs.SimulationResult]:
    """(first leg to t_a, second leg t_a -> t_end started from the first leg's final state)."""
    first = idm_rs.simulate(P, kw.pop("waveform"), t_end=t_a, **kw)
    second = idm_rs.simulate(P, first.waveform, t_start=t_a, t_end=t_end, initial_state=first.final_state, **kw)
    return first, second


def test_lps_paper_case_continued_at_4ms_equals_the_10ms_run_bitwise():
    whole = idm_rs.simulate(P, PAPER_WAVE, t_end=10e-3, dt=1e-8, model="lps")
    first, second = _split(4e-3, 10e-3, waveform=PAPER_WAVE, dt=1e-8, model="lps")
    assert first.final_state.t == 4e-3
    np.testing.assert_array_equal(np.asarray(second.final_state), np.asarray(whole.final_state))
    assert second.final_position == whole.final_position
    # the motion is not trivial: the body moved by more than a micrometre
    assert abs(whole.final_position) > 1e-6


def test_dps_with_a_sensor_lag_state_continued_bitwise():
    effects = idm_rs.Effects(tau_sensor=2e-5)
    kw = dict(dt=1e-8, model="dps", n_elements=4, effects=effects)
    whole = idm_rs.simulate(P, SHORT_WAVE, t_end=2e-3, **kw)
    assert "x_sensor" in [n for n, _ in whole.final_state.components]
    first, second = _split(0.7e-3, 2e-3, waveform=SHORT_WAVE, **kw)
    np.testing.assert_array_equal(np.asarray(second.final_state), np.asarray(whole.final_state))
    assert second.final_position == whole.final_position
    # the lagged reading is part of the state, so the continued reading is the same too
    assert second.reading[-1] == whole.reading[-1]
    assert second.final_state["x_sensor"] == whole.final_state["x_sensor"]


def test_continuation_across_the_voltage_peak_breakpoint_is_bitwise():
    """Split exactly on the waveform's breakpoint (0.5 ms, the peak), then mid-slope."""
    whole = idm_rs.simulate(P, PAPER_WAVE, t_end=2e-3, dt=1e-8, model="lps")
    for t_a in (0.5e-3, 0.37e-3, 1.23e-3):
        _, second = _split(t_a, 2e-3, waveform=PAPER_WAVE, dt=1e-8, model="lps")
        assert second.final_position == whole.final_position, t_a


def test_energy_budget_continues_from_the_accounting_states():
    kw = dict(dt=1e-8, model="lps", energy=True)
    whole = idm_rs.simulate(P, SHORT_WAVE, t_end=2e-3, **kw)
    first, second = _split(0.8e-3, 2e-3, waveform=SHORT_WAVE, **kw)
    np.testing.assert_array_equal(np.asarray(second.final_state), np.asarray(whole.final_state))
    assert second.energy is not None and whole.energy is not None
    # the works are integrals from t = 0, carried across the split in the state
    assert second.energy.input_work[0] == first.energy.input_work[-1] != 0.0
    assert second.energy.input_work[-1] == whole.energy.input_work[-1]
    assert second.energy.friction_work[-1] == whole.energy.friction_work[-1]


def test_continued_run_saves_from_t_start_to_t_end():
    first, second = _split(1e-3, 2e-3, waveform=SHORT_WAVE, dt=1e-8, model="lps", save_every=100)
    assert second.t[0] == 1e-3 and second.t[-1] == 2e-3
    assert second.final_state.t == 2e-3
    # the first saved state of the second leg is the first leg's last one
    assert second.nodes[0, 0] == first.nodes[-1, 0]
    assert second.fh[0] == first.fh[-1]


def test_dopri5_continuation_agrees_to_well_below_a_nanometre():
    """Not bitwise (the adaptive steps differ), but within the tolerance."""
    kw = dict(model="lps", method="dopri5", rtol=1e-8, atol=1e-8)
    whole = idm_rs.simulate(P, PAPER_WAVE, t_end=10e-3, **kw)
    _, second = _split(4e-3, 10e-3, waveform=PAPER_WAVE, **kw)
    assert second.final_state.t == 10e-3
    assert abs(second.final_position - whole.final_position) < 1e-10


@pytest.mark.parametrize(
    "t_start, t_end, match",
    [
        (2e-3, 1e-3, "t_start"),  # after t_end
        (1e-3, 1e-3, "t_start"),  # empty span
        (-1e-3, 1e-3, "t_start"),  # negative
        (1e-3 + 3e-9, 2e-3, "t_start"),  # off the RK4 step grid
    ],
)
def test_invalid_t_start_is_refused_naming_it(t_start, t_end, match):
    with pytest.raises(ValueError, match=match):
        idm_rs.simulate(P, SHORT_WAVE, t_start=t_start, t_end=t_end, dt=1e-8, model="lps")
