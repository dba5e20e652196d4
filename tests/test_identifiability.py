"""Which fitted parameters the experiments determine (diagnosis/identifiability.py): the 95 %
interval from the Fisher matrix, the 25 % rule, and the partner a parameter trades off against."""

from __future__ import annotations

import math

import pytest

from idm_rs.diagnosis.identifiability import Z95, assess
from idm_rs.diagnosis.thresholds import DETERMINED_WITHIN


def test_a_tight_parameter_is_determined_and_a_loose_one_is_not():
    values = {"kappa": 0.009, "tau_creep": 0.005, "mu_k": 0.48}
    # kappa +-100 % at 1 sigma, tau_creep +-5 %, mu_k +-0.5 %
    std = {"kappa": 0.009, "tau_creep": 2.5e-4, "mu_k": 0.0024}
    corr = {"kappa": {"tau_creep": -0.97, "mu_k": 0.1}, "tau_creep": {"kappa": -0.97}, "mu_k": {"kappa": 0.1}}
    s = {p.name: p for p in assess(values, std, corr, ["kappa", "tau_creep", "mu_k"])}
    assert not s["kappa"].determined and s["kappa"].partner == "tau_creep"
    assert s["kappa"].correlation == pytest.approx(-0.97)
    assert s["kappa"].low == pytest.approx(0.009 - Z95 * 0.009)
    assert s["kappa"].high == pytest.approx(0.009 + Z95 * 0.009)
    assert s["tau_creep"].determined and s["mu_k"].determined
    assert "NOT determined" in s["kappa"].words() and "tau_creep" in s["kappa"].words()
    assert "determined" in s["mu_k"].words() and "NOT" not in s["mu_k"].words()


def test_the_rule_is_the_25_percent_half_width_at_95_percent():
    v = 1.0
    at_edge = DETERMINED_WITHIN * v / Z95
    inside = assess({"a": v}, {"a": 0.999 * at_edge}, {}, ["a"])[0]
    outside = assess({"a": v}, {"a": 1.001 * at_edge}, {}, ["a"])[0]
    assert inside.determined and not outside.determined
    assert outside.partner is None  # no correlation given: no partner named


def test_an_unknown_or_infinite_sigma_is_not_determined():
    s = assess({"a": 2.0, "b": 0.0}, {"a": math.inf}, {}, ["a", "b", "missing"])
    assert [p.name for p in s] == ["a", "b"]
    assert not s[0].determined and not s[1].determined
