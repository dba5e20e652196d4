"""Adaptive single runs, ``simulate(..., method="dopri5")``: the paper case agrees with the RK4
reference, with far fewer steps, and the result says how it was computed."""

from __future__ import annotations

import math
import re

import numpy as np
import pytest

import idm_rs

P = idm_rs.Params()
PAPER_WAVE = idm_rs.Triangle(80.0, 0.5e-3, 9.5e-3)


@pytest.fixture(scope="module")
def rk4() -> idm_rs.SimulationResult:
    return idm_rs.simulate(P, PAPER_WAVE, t_end=10e-3, dt=1e-8, model="lps")


@pytest.fixture(scope="module")
def dopri5() -> idm_rs.SimulationResult:
    return idm_rs.simulate(P, PAPER_WAVE, t_end=10e-3, model="lps", method="dopri5", rtol=1e-8, atol=1e-8)


def test_dopri5_paper_case_agrees_with_rk4_within_a_nanometre(rk4, dopri5):
    assert abs(dopri5.final_position - rk4.final_position) < 1e-9
    # and the whole final state, on each component's scale
    np.testing.assert_allclose(dopri5.final_state.nodes, rk4.final_state.nodes, rtol=0, atol=1e-9)
    assert abs(dopri5.final_state["fh"] - rk4.final_state["fh"]) < 1e-3  # N, |Fh| ~ 0.45 N


def test_dopri5_saves_fewer_points_than_rk4(rk4, dopri5):
    # same save_every (100 accepted steps): the adaptive run takes far fewer steps
    assert len(dopri5.t) < len(rk4.t) / 10
    assert dopri5.t[0] == 0.0 and dopri5.t[-1] == 10e-3
    assert np.all(np.diff(dopri5.t) > 0)


def test_dopri5_steps_exactly_onto_the_voltage_peak():
    r = idm_rs.simulate(P, PAPER_WAVE, t_end=1e-3, model="lps", method="dopri5", rtol=1e-8, atol=1e-8, save_every=1)
    assert 0.5e-3 in r.t
    assert r.voltage[list(r.t).index(0.5e-3)] == 80.0


def test_dopri5_result_records_its_method_and_tolerances(dopri5, rk4):
    assert dopri5.method == "dopri5"
    assert dopri5.rtol == 1e-8 and dopri5.atol == 1e-8
    assert dopri5.final_state.t == 10e-3
    assert rk4.method == "rk4" and math.isnan(rk4.rtol) and math.isnan(rk4.atol)


def test_dopri5_to_xarray_attrs_carry_method_and_rtol(dopri5, rk4):
    attrs = dopri5.to_xarray().attrs
    assert attrs["method"] == "dopri5"
    assert attrs["rtol"] == 1e-8 and attrs["atol"] == 1e-8
    assert rk4.to_xarray().attrs["method"] == "rk4"


def test_dopri5_needs_no_step_on_the_grid():
    """RK4 refuses a dt that does not divide the span; the adaptive run has no such grid."""
    with pytest.raises(ValueError, match="dt"):
        idm_rs.simulate(P, PAPER_WAVE, t_end=1e-3, dt=3e-8, model="lps")
    r = idm_rs.simulate(P, PAPER_WAVE, t_end=1e-3, model="lps", method="dopri5", first_step=3e-8)
    assert r.t[-1] == 1e-3


def test_looser_tolerance_takes_fewer_steps():
    kw = dict(t_end=2e-3, model="lps", method="dopri5", save_every=1)
    tight = idm_rs.simulate(P, PAPER_WAVE, rtol=1e-9, atol=1e-9, **kw)
    loose = idm_rs.simulate(P, PAPER_WAVE, rtol=1e-5, atol=1e-5, **kw)
    assert len(loose.t) < len(tight.t)


@pytest.mark.parametrize("bad", [dict(rtol=0.0), dict(atol=-1.0), dict(first_step=0.0)])
def test_non_positive_tolerance_or_first_step_is_refused(bad):
    with pytest.raises(ValueError, match=next(iter(bad))):
        idm_rs.simulate(P, PAPER_WAVE, t_end=1e-3, model="lps", method="dopri5", **bad)


def test_unknown_method_is_named():
    with pytest.raises(ValueError, match="'method'"):
        idm_rs.simulate(P, PAPER_WAVE, t_end=1e-3, model="lps", method="euler")  # type: ignore[arg-type]


# --- rodas4 (linearly implicit Rosenbrock) and "auto" ---------------------------------------------


def test_rodas4_paper_case_agrees_with_rk4_within_a_nanometre(rk4):
    r = idm_rs.simulate(P, PAPER_WAVE, t_end=10e-3, model="lps", method="rodas4", rtol=1e-6, atol=1e-6)
    assert abs(r.final_position - rk4.final_position) < 1e-9
    assert r.method == "rodas4" and r.rtol == 1e-6
    assert r.t[-1] == 10e-3


def test_rodas4_keeps_the_presliding_force_within_its_bound():
    """A light weight at high voltage: the linearised step can overshoot |Fh| <= Fs; such steps
    are rejected, so every accepted state respects the bound (the exact solution does)."""
    p = idm_rs.Params(m2=0.25 * P.m1)
    r = idm_rs.simulate(p, idm_rs.Triangle(98.67, 0.5e-3, 9.5e-3), t_end=10e-3, model="lps", method="rodas4",
                        rtol=1e-3, atol=1e-3, save_every=1)
    fs = max(p.mu_s, p.mu_k) * p.effective_normal_force
    assert np.abs(r.fh).max() <= fs * (1 + 1e-6)


def test_auto_resolves_to_the_measured_setting(rk4):
    r = idm_rs.simulate(P, PAPER_WAVE, t_end=10e-3, model="lps", method="auto")
    method, rtol, atol = idm_rs.core.methods.AUTO
    assert (r.method, r.rtol, r.atol) == (method, rtol, atol)
    assert abs(r.final_position - rk4.final_position) < 1e-9


# --- stiffness: "auto" notices it, "dopri5" says so instead of crawling ------------------------

NEAR_FRICTIONLESS = idm_rs.Params(mu_k=1e-6, mu_s=1e-6)
SMALL_TRIANGLE = idm_rs.Triangle(50.0, 0.5e-3, 0.5e-3)


def test_a_near_frictionless_device_stops_dopri5_with_a_hint_instead_of_crawling():
    method = "dopri5"
    # the case: it ran for more than a minute without a word (2e8 steps); now it stops once
    # its pace projects more than 1e8 (after 0.74 M steps); Rodas4 takes milliseconds
    with pytest.raises(idm_rs.DivergenceError, match=r"integration stopped at t = .*the step fell to .*stability "
                                                     r"limit .*use method 'rodas4' or 'auto'") as e:
        idm_rs.simulate(NEAR_FRICTIONLESS, SMALL_TRIANGLE, t_end=1e-3, model="lps", method=method)
    so_far = int(re.search(r"(\d+) steps so far", str(e.value)).group(1))
    assert so_far < 2_000_000, str(e.value)
    r = idm_rs.simulate(NEAR_FRICTIONLESS, SMALL_TRIANGLE, t_end=1e-3, model="lps", method="rodas4")
    assert r.complete and math.isfinite(r.final_position)


#: accepted steps at the stability limit before `auto` tries Rodas4 (rust/src/integrate/stiffness.rs)
TRY_IMPLICIT_AFTER = 256


def test_auto_runs_a_near_frictionless_device_as_fast_as_rodas4_and_as_accurately():
    kw = dict(t_end=1e-3, model="lps", save_every=1)
    auto = idm_rs.simulate(NEAR_FRICTIONLESS, SMALL_TRIANGLE, method="auto", **kw)
    ref = idm_rs.simulate(NEAR_FRICTIONLESS, SMALL_TRIANGLE, method="rodas4", rtol=1e-9, atol=1e-9, **kw)
    ro = idm_rs.simulate(NEAR_FRICTIONLESS, SMALL_TRIANGLE, method="rodas4", rtol=1e-6, atol=1e-6, **kw)
    assert abs(auto.final_position - ref.final_position) < 1e-9
    # the explicit steps before the switch (TRY_IMPLICIT_AFTER = 256 of them at the stability
    # limit, integrate/stiffness.rs), then Rodas4's own (measured: 613 saved times against 181)
    assert len(auto.t) < 1.5 * len(ro.t) + 2 * TRY_IMPLICIT_AFTER, (len(auto.t), len(ro.t))


def test_auto_hands_only_the_stiff_points_of_a_sweep_to_rodas4():
    # the stiff grid, smaller: presliding stiffness up to 10x the paper's 2e10 N/m
    grid = {"fric_alpha": [2e10, 2e11], "voltage": [60.0, 100.0]}
    kw = dict(t_end=2e-3, model="lps", progress=False)
    auto = idm_rs.sweep(P, PAPER_WAVE, grid, method="auto", **kw)
    dp = idm_rs.sweep(P, PAPER_WAVE, grid, method="dopri5", rtol=3e-7, atol=3e-7, **kw)
    ro = idm_rs.sweep(P, PAPER_WAVE, grid, method="rodas4", rtol=1e-6, atol=1e-6, **kw)
    ref = idm_rs.sweep(P, PAPER_WAVE, grid, method="rodas4", rtol=1e-9, atol=1e-9, **kw)
    assert (auto.status.values == 1).all()
    assert np.abs(auto.final_position.values - ref.final_position.values).max() < 1e-9
    # the paper's friction: Dormand-Prince's step count (stiff for a moment at most, then back);
    # ten times stiffer: Rodas4's
    paper, stiff = auto.steps.values[0], auto.steps.values[1]
    assert (paper <= 1.2 * dp.steps.values[0]).all(), (paper, dp.steps.values[0])
    # (each stretch back on Dormand-Prince pays TRY_IMPLICIT_AFTER steps before the next trial;
    # measured 2,503 and 1,685 against Rodas4's 1,287 and 698 and Dormand-Prince's 51,597, 105,714)
    assert (stiff < 2 * ro.steps.values[1] + 4 * TRY_IMPLICIT_AFTER).all(), (stiff, ro.steps.values[1])
    assert (stiff < dp.steps.values[1] / 20).all(), (stiff, dp.steps.values[1])


def test_a_crawling_sweep_point_is_diverged_with_the_method_s_reason():
    # (that its neighbours in a lane group finish bitwise as alone: the Rust test
    # a_crawling_lane_stops_as_on_the_scalar_path_and_its_neighbours_finish)
    ds = idm_rs.sweep(NEAR_FRICTIONLESS, SMALL_TRIANGLE, {"voltage": [30.0, 50.0]}, t_end=1e-3, model="lps",
                      method="dopri5", progress=False)
    assert (ds.status.values == 3).all()
    for reason in ds.reason.values:
        assert "the step fell to" in str(reason) and "use method 'rodas4'" in str(reason), reason
