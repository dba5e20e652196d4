"""The public batch API (``idm_rs.core.batch``: Point, Structure, Tables, start, run): each point of a
batch is the same computation as ``simulate`` (bitwise with RK4), final states come back per
point and restart a batch mid-record, an invalid point is flagged while the others run, and
input errors are named. LPS, spans of 1-2 ms: the file runs in a couple of seconds."""

from __future__ import annotations

import math

import numpy as np
import pytest

import idm_rs
import idm_rs.core.batch
from idm_rs.core.batch import Point, Structure, Tables, run, start

P = idm_rs.Params()
WAVE = idm_rs.Triangle(80.0, 0.3e-3, 0.7e-3)  # up and back down within 1 ms
LPS = Structure("lps")
M2S = (0.2, 0.3, 0.45)


@pytest.fixture(scope="module")
def points() -> list[Point]:
    return [Point(P.replace(m2=m2), waveform=WAVE) for m2 in M2S]


@pytest.fixture(scope="module")
def sims(points) -> list[idm_rs.SimulationResult]:
    return [idm_rs.simulate(pt.params, WAVE, t_end=2e-3, dt=1e-8, model="lps") for pt in points]


def test_batch_is_a_submodule_of_the_package():
    assert idm_rs.core.batch.run is run
    assert {"Point", "Structure", "Tables", "start", "run"} <= set(vars(idm_rs.core.batch))


def test_each_point_equals_simulate_bitwise(points, sims):
    out = run(points, LPS, t_end=2e-3, dt=1e-8)
    assert list(out["status"]) == [1, 1, 1]
    for i, s in enumerate(sims):
        assert out["final_position"][i] == s.final_position, M2S[i]
    # the points differ: the mass ratio matters
    assert len(set(out["final_position"])) == 3
    assert list(out["steps"]) == [200_000] * 3
    assert list(out["dt_used"]) == [1e-8] * 3


def test_final_states_are_simulates_final_states(points, sims):
    out = run(points, LPS, t_end=2e-3, dt=1e-8, final_states=True)
    fs = out["final_states"]
    assert fs.shape == (3, 7) and fs.dtype == np.float64
    for i, s in enumerate(sims):
        np.testing.assert_array_equal(fs[i], np.asarray(s.final_state))


def test_final_states_are_absent_unless_asked(points):
    out = run(points[:1], LPS, t_end=1e-3, dt=1e-8)
    assert "final_states" not in out and "traces" not in out


def test_batch_restarted_from_the_states_of_a_2ms_run_equals_the_whole_run(points):
    whole = run(points, LPS, t_end=3e-3, dt=1e-8, final_states=True)
    head = run(points, LPS, t_end=2e-3, dt=1e-8, final_states=True)
    tail_points = [Point(pt.params, waveform=WAVE, t_start=2e-3, initial_state=head["final_states"][i])
                   for i, pt in enumerate(points)]
    tables = Tables.from_points(tail_points)
    assert tables.t_starts is not None and tables.initial_states is not None
    assert tables.initial_states.shape == (3, 7)
    tail = run(tables, LPS, t_end=3e-3, dt=1e-8, final_states=True)
    assert list(tail["status"]) == [1, 1, 1]
    assert list(tail["steps"]) == [100_000] * 3
    np.testing.assert_array_equal(tail["final_position"], whole["final_position"])
    np.testing.assert_array_equal(tail["final_states"], whole["final_states"])


def test_batch_restart_from_simulate_states_with_an_effect_state_on_dps():
    effects = idm_rs.Effects(tau_sensor=2e-5)
    dps = Structure("dps", 4)
    whole = idm_rs.simulate(P, WAVE, t_end=1.5e-3, dt=1e-8, model="dps", effects=effects)
    head = idm_rs.simulate(P, WAVE, t_end=0.6e-3, dt=1e-8, model="dps", effects=effects)
    pt = Point(P, effects, WAVE, t_start=0.6e-3, initial_state=head.final_state)
    out = run([pt], dps, t_end=1.5e-3, dt=1e-8, final_states=True)
    assert out["final_states"].shape == (1, 14)
    np.testing.assert_array_equal(out["final_states"][0], np.asarray(whole.final_state))


def test_recorded_readings_are_simulates_readings(points):
    out = run(points[:2], LPS, t_end=1e-3, dt=1e-8, record_every=100)
    assert len(out["traces"]) == 2
    for pt, trace in zip(points[:2], out["traces"]):
        r = idm_rs.simulate(pt.params, WAVE, t_end=1e-3, dt=1e-8, model="lps", save_every=100)
        np.testing.assert_array_equal(trace, r.reading)


def test_per_point_t_end_overrides_the_batch_span(points):
    pts = [Point(points[0].params, waveform=WAVE, t_end=1e-3), points[0]]
    out = run(pts, LPS, t_end=2e-3, dt=1e-8)
    short = idm_rs.simulate(points[0].params, WAVE, t_end=1e-3, dt=1e-8, model="lps")
    assert out["final_position"][0] == short.final_position
    assert list(out["steps"]) == [100_000, 200_000]


def test_an_invalid_point_is_flagged_while_the_others_run(points, sims):
    bad = {**P.to_dict(resolved=False), "m2": -1.0}
    pts = [points[0], Point(bad, waveform=WAVE), points[2]]
    out = run(pts, LPS, t_end=2e-3, dt=1e-8)
    assert list(out["status"]) == [1, 4, 1]
    assert math.isnan(out["final_position"][1])
    assert out["final_position"][0] == sims[0].final_position
    assert out["final_position"][2] == sims[2].final_position


def test_an_invalid_initial_state_flags_its_point(points):
    too_much_fh = np.zeros(7)
    too_much_fh[5] = 50.0  # N, beyond the presliding bound
    pts = [Point(points[0].params, waveform=WAVE, t_start=1e-4, initial_state=too_much_fh),
           Point(points[1].params, waveform=WAVE, t_start=1e-4, initial_state=np.zeros(7))]
    out = run(pts, LPS, t_end=1e-3, dt=1e-8)
    assert list(out["status"]) == [4, 1]


def test_mixing_waveform_families_is_refused():
    with pytest.raises(ValueError, match="one waveform family"):
        run([Point(P, waveform=WAVE), Point(P, waveform=idm_rs.Sawtooth())], LPS, t_end=1e-3)


def test_a_point_without_a_waveform_is_refused():
    with pytest.raises(ValueError, match="waveform"):
        Tables.from_points([Point(P)])


def test_initial_states_for_some_points_only_is_refused():
    with pytest.raises(ValueError, match="initial state"):
        Tables.from_points([Point(P, waveform=WAVE, initial_state=np.zeros(7)), Point(P, waveform=WAVE)])


def test_recording_with_dopri5_is_refused():
    with pytest.raises(ValueError, match="rk4"):
        run([Point(P, waveform=WAVE)], LPS, t_end=1e-3, method="dopri5", record_every=10)


def test_dopri5_batch_point_equals_dopri5_simulate():
    out = run([Point(P, waveform=WAVE)], LPS, t_end=2e-3, method="dopri5", rtol=1e-8, atol=1e-8)
    r = idm_rs.simulate(P, WAVE, t_end=2e-3, model="lps", method="dopri5", rtol=1e-8, atol=1e-8)
    assert out["final_position"][0] == r.final_position
    assert out["steps"][0] < 200_000 / 5


def test_start_returns_a_handle_with_progress_and_a_single_result(points):
    handle = start(Tables.from_points(points), LPS, t_end=1e-3, dt=1e-8, threads=2)
    assert handle.total == 3
    while not handle.wait(0.05):
        pass
    assert handle.progress() == 3
    out = handle.result()
    assert list(out["status"]) == [1, 1, 1]
    with pytest.raises(RuntimeError, match="already taken"):
        handle.result()


def test_threads_do_not_change_the_results(points):
    one = run(points, LPS, t_end=1e-3, dt=1e-8, threads=1)
    three = run(points, LPS, t_end=1e-3, dt=1e-8, threads=3)
    np.testing.assert_array_equal(one["final_position"], three["final_position"])


# --- final states of invalid points and of mixed state layouts -------------


def test_final_states_of_a_batch_whose_points_are_all_invalid():
    bad = {**P.to_dict(resolved=False), "m2": -1.0}
    out = run([Point(bad, waveform=WAVE)], LPS, t_end=1e-3, dt=1e-8, final_states=True)
    assert list(out["status"]) == [4]
    assert out["final_states"].shape[0] == 1 and np.all(np.isnan(out["final_states"]))


def test_final_states_of_points_with_different_state_layouts():
    """Points whose states differ in length (a sensor lag adds a component) in one batch: each
    row is that point's own final state, bit for bit what ``simulate()`` ends in."""
    effects = idm_rs.Effects(tau_sensor=2e-5)
    pts = [Point(P, waveform=WAVE), Point(P, effects, WAVE)]
    out = run(pts, LPS, t_end=1e-3, dt=1e-8, final_states=True)
    assert list(out["status"]) == [1, 1]
    for row, e in zip(out["final_states"], (idm_rs.Effects(), effects)):
        r = idm_rs.simulate(P, WAVE, t_end=1e-3, dt=1e-8, model="lps", effects=e)
        np.testing.assert_array_equal(np.asarray(row, dtype=float), np.asarray(r.final_state, dtype=float))
    assert len(out["final_states"][1]) == len(out["final_states"][0]) + 1
