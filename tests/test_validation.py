"""Bad input is refused up front with an error that names what is wrong; a run that diverges
says when and what step to try; the Rust core releases the GIL."""

from __future__ import annotations

import math
import re
import threading
import time

import numpy as np
import pytest

import idm_rs
from idm_rs.core import engine

PAPER_WAVE = idm_rs.Triangle(amplitude=80.0, rise=0.5e-3, fall=9.5e-3)
SHORT_WAVE = idm_rs.Triangle(amplitude=80.0, rise=0.5e-3, fall=0.5e-3)


# --------------------------------------------------------------------------------------------
# parameters
# --------------------------------------------------------------------------------------------
@pytest.mark.parametrize(
    "name,value,why",
    [
        ("m1", -1.0, "positive"),
        ("m2", 0.0, "positive"),
        ("d33", math.nan, "finite"),
        ("pe_youngs", math.inf, "finite"),
        ("pe_area", 0.0, "positive"),
        ("pe_length", -2e-2, "positive"),
        ("pe_density", -1.0, "non-negative"),
        ("normal_force", 0.0, "positive"),
        ("fric_beta", -1.0, "non-negative"),
        ("sigma1", -math.inf, "finite"),
        ("mu_k", 0.0, "positive"),
    ],
)
def test_bad_parameter_value_is_named(name, value, why):
    with pytest.raises(ValueError, match=rf"'{name}' must be {why}, got "):
        idm_rs.Params(**{name: value})


def test_non_numeric_parameter_is_a_type_error_naming_it():
    with pytest.raises(TypeError, match="'m1'"):
        idm_rs.Params(m1="heavy")


def test_unknown_parameter_name_is_named():
    with pytest.raises(TypeError, match="'mass'"):
        idm_rs.Params(mass=1)
    with pytest.raises(ValueError, match="'mass'"):
        idm_rs.Params.from_dict({"mass": 1})
    with pytest.raises(ValueError, match="'mass'"):
        idm_rs.Params().replace(mass=1)


def test_presliding_bound_must_exist():
    """b + c <= 0 would leave Fh unbounded: refused, naming both parameters."""
    with pytest.raises(ValueError, match="'fric_beta' \\+ 'fric_gamma'"):
        idm_rs.Params(fric_beta=1e9, fric_gamma=-1e9)


def test_valid_parameters_round_trip_and_default_normal_force():
    p = idm_rs.Params.from_dict({"m2": 0.6})
    assert p.effective_normal_force == pytest.approx((0.4 + 0.6 + 4e-3) * 9.81, rel=1e-15)
    assert p.to_dict()["normal_force"] == pytest.approx(p.effective_normal_force, rel=1e-15)
    assert idm_rs.Params(m2=0.6, normal_force=3.9).to_dict()["normal_force"] == 3.9


# --------------------------------------------------------------------------------------------
# simulate() arguments
# --------------------------------------------------------------------------------------------
def test_unknown_model_is_named():
    with pytest.raises(ValueError, match="'model'.*'fem'"):
        idm_rs.simulate(idm_rs.Params(), SHORT_WAVE, 1e-3, model="fem")


def test_zero_elements_is_named():
    with pytest.raises(ValueError, match="'n_elements'"):
        idm_rs.simulate(idm_rs.Params(), SHORT_WAVE, 1e-3, model="dps", n_elements=0)


def test_zero_save_every_is_named():
    with pytest.raises(ValueError, match="'save_every'"):
        idm_rs.simulate(idm_rs.Params(), SHORT_WAVE, 1e-3, save_every=0)


@pytest.mark.parametrize("kw,name", [({"n_elements": -1}, "n_elements"), ({"save_every": -1}, "save_every")])
def test_negative_counts_are_named(kw, name):
    with pytest.raises(ValueError, match=f"'{name}'"):
        idm_rs.simulate(idm_rs.Params(), SHORT_WAVE, 1e-3, **kw)


@pytest.mark.parametrize("dt", [0.0, -1e-8, math.nan, math.inf])
def test_non_positive_dt_is_named(dt):
    with pytest.raises(ValueError, match="'dt'"):
        idm_rs.simulate(idm_rs.Params(), SHORT_WAVE, 1e-3, dt=dt)


def test_dt_not_dividing_t_end_is_refused():
    # dt divides every breakpoint (0.5 ms, 1 ms) but not t_end: the message blames t_end
    with pytest.raises(ValueError, match="t_end"):
        idm_rs.simulate(idm_rs.Params(), SHORT_WAVE, 1e-3 + 1e-8, dt=2e-8)


def test_dt_not_dividing_a_breakpoint_suggests_one():
    """Breakpoint at 0.5 ms, dt = 3e-7 s (which divides t_end = 0.9 ms but not 0.5 ms)."""
    w = idm_rs.Triangle(amplitude=80.0, rise=0.5e-3, fall=0.4e-3)
    with pytest.raises(ValueError, match="breakpoint") as exc:
        idm_rs.simulate(idm_rs.Params(), w, 0.9e-3, dt=3e-7, model="lps")
    msg = str(exc.value)
    assert "5e-4" in msg  # names the offending breakpoint
    m = re.search(r"dt = ([0-9.eE+-]+) s divides", msg)
    assert m, msg
    suggested = float(m.group(1))
    assert suggested < 3e-7
    # the suggestion works
    r = idm_rs.simulate(idm_rs.Params(), w, 0.9e-3, dt=suggested, model="lps", save_every=1000)
    assert np.isfinite(r.final_position)


def test_dt_too_large_for_the_dps_structure_is_refused_up_front():
    """100 elements at dt = 1e-7 s: the bar's fastest modes, pushed onto the negative real axis
    by the stiffness-proportional damping (|λ| = 4.1e8 1/s), need dt <= 5.96e-9 s: refused
    before integrating, naming the mode, the limit and a step that fits the input. 40 elements
    at 1e-7 s, once let through (its undamped ω dt = 1.15 is stable) and then diverging at
    0.9 µs with the friction blamed, is refused the same way (limit 3.84e-8 s)."""
    with pytest.raises(ValueError, match="unstable for the structure's fastest mode") as exc:
        idm_rs.simulate(idm_rs.Params(), SHORT_WAVE, 1e-3, dt=1e-7, model="dps", n_elements=100)
    m = re.search(r"use dt <= ([0-9.eE+-]+) s", str(exc.value))
    assert m, str(exc.value)
    limit = engine.rk4_step_limit(idm_rs.Params()._given(), engine.RunConfig(model="dps", n_elements=100))
    assert float(m.group(1)) == pytest.approx(limit, rel=1e-3) and 5.9e-9 < limit < 6.0e-9
    assert "overdamped mode at 4.13" in str(exc.value) and "dt = 5e-9 s fits this input" in str(exc.value)
    with pytest.raises(ValueError, match=r"use dt <= 3\.84\de-8 s"):
        idm_rs.simulate(idm_rs.Params(), SHORT_WAVE, 1e-3, dt=1e-7, model="dps", n_elements=40)


def test_a_coarse_bar_is_held_by_its_undamped_frequency_as_before():
    """4 elements: the damping barely moves the fastest mode; the limit stays within 3 % of
    2.5 / ω (the rule for an undamped structure)."""
    config = engine.RunConfig(model="dps", n_elements=4)
    w = engine.highest_frequency(idm_rs.Params()._given(), config)
    assert engine.rk4_step_limit(idm_rs.Params()._given(), config) * w == pytest.approx(2.5, rel=0.03)


def test_diverging_step_raises_divergence_error_with_time_and_hint():
    """LPS paper case at dt = 5e-7 s diverges once sliding starts (MODEL.md): DivergenceError (a
    RuntimeError) whose message is the text, says when (also as ``exc.t`` [s]) and which dt to
    try; that hint (fitted to the breakpoints and the span) then works."""
    with pytest.raises(idm_rs.DivergenceError) as exc:
        idm_rs.simulate(idm_rs.Params(), PAPER_WAVE, 10e-3, dt=5e-7, model="lps")
    e = exc.value
    assert isinstance(e, RuntimeError)
    msg = str(e)
    assert msg.startswith("integration diverged"), msg
    assert 0 < e.t < 10e-3
    when = re.search(r"diverged at t = ([0-9.eE+-]+) s", msg)
    assert when and float(when.group(1)) == pytest.approx(e.t, rel=1e-6), msg
    assert "try dt" in msg
    hint = float(re.search(r"try dt = ([0-9.eE+-]+) s", msg).group(1))
    assert 5e-7 / 64 <= hint < 5e-7
    # the hint already fits the breakpoints and the span: used as it is, it works
    x = idm_rs.simulate(idm_rs.Params(), PAPER_WAVE, 10e-3, dt=hint, model="lps", save_every=10**7).final_position
    assert abs(x - 1.678e-6) < 1e-9


# --------------------------------------------------------------------------------------------
# waveforms
# --------------------------------------------------------------------------------------------
@pytest.mark.parametrize("rise", [1e-2, 2e-2])
def test_sawtooth_rise_must_be_shorter_than_the_period(rise):
    with pytest.raises(ValueError, match="'rise'.*period"):
        idm_rs.Sawtooth(amplitude=80.0, frequency=100.0, rise=rise)


@pytest.mark.parametrize("t", [[0.0, 1e-3, 1e-3], [0.0, 2e-3, 1e-3]])
def test_sampled_times_must_increase(t):
    with pytest.raises(ValueError, match="increase strictly"):
        idm_rs.Sampled(t, [0.0, 1.0, 2.0])


def test_sampled_length_mismatch_and_nan_are_refused():
    with pytest.raises(ValueError, match="3 times but 2 voltages"):
        idm_rs.Sampled([0.0, 1e-3, 2e-3], [0.0, 1.0])
    with pytest.raises(ValueError, match="not finite"):
        idm_rs.Sampled([0.0, 1e-3], [0.0, math.nan])


def test_triangle_times_must_be_positive():
    with pytest.raises(ValueError, match="'rise'"):
        idm_rs.Triangle(amplitude=80.0, rise=-1e-3, fall=1e-3)
    with pytest.raises(ValueError, match="'fall'"):
        idm_rs.Triangle(amplitude=80.0, rise=1e-3, fall=0.0)


def test_sampled_equals_triangle_through_the_same_points():
    """A Sampled waveform through a Triangle's breakpoints gives the identical run."""
    tri = idm_rs.Triangle(amplitude=60.0, rise=0.3e-3, fall=0.7e-3)
    smp = idm_rs.Sampled(*tri.breakpoints())
    a = idm_rs.simulate(idm_rs.Params(), tri, 1.5e-3, 1e-8, save_every=100)
    b = idm_rs.simulate(idm_rs.Params(), smp, 1.5e-3, 1e-8, save_every=100)
    assert np.array_equal(a.nodes, b.nodes)


# --------------------------------------------------------------------------------------------
# the GIL
# --------------------------------------------------------------------------------------------
def _run(model: str, amplitude: float):
    w = idm_rs.Triangle(amplitude=amplitude, rise=0.5e-3, fall=9.5e-3)
    return idm_rs.simulate(idm_rs.Params(), w, 10e-3, 1e-8, model=model, n_elements=4, save_every=1000)


def test_two_threads_run_concurrently_and_match_sequential_runs():
    jobs = [("dps", 80.0), ("lps", -60.0)]
    sequential = [_run(*j) for j in jobs]
    results: list = [None, None]
    errors: list = []

    def work(i):
        try:
            results[i] = _run(*jobs[i])
        except BaseException as e:  # pragma: no cover - reported below
            errors.append(e)

    threads = [threading.Thread(target=work, args=(i,)) for i in range(2)]
    for th in threads:
        th.start()
    for th in threads:
        th.join(timeout=60)
    assert not any(th.is_alive() for th in threads), "a simulation thread did not finish"
    assert not errors, errors
    for seq, par in zip(sequential, results):
        assert np.array_equal(seq.nodes, par.nodes)
        assert np.array_equal(seq.fh, par.fh)
        assert seq.final_position == par.final_position


def test_python_threads_progress_while_the_core_runs():
    """While one thread is inside the Rust core, another Python thread keeps running (it could
    not if the GIL were held): a 1 ms heartbeat keeps beating during the ~0.3 s call (a held
    GIL would allow at most a beat or two at the edges of the call)."""
    beats: list[float] = []
    stop = threading.Event()

    def heartbeat():
        while not stop.is_set():
            beats.append(time.perf_counter())
            time.sleep(1e-3)

    th = threading.Thread(target=heartbeat)
    th.start()
    try:
        time.sleep(0.01)
        t0 = time.perf_counter()
        _run("dps", 80.0)
        t1 = time.perf_counter()
    finally:
        stop.set()
        th.join()
    inside = [b for b in beats if t0 < b < t1]
    assert len(inside) >= 5, f"{len(inside)} heartbeats during a {t1 - t0:.3f} s simulation"
