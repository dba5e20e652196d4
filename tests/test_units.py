"""Numbers as people read them: SI prefixes and units in every printout (before: "0.000000 um"
for 2.5e-14 m, intervals "[1.24e-07, 1.24e-07]", steady states and stall forces without units)."""

from __future__ import annotations

import math

import numpy as np

from idm_rs.apps.actuator import StallForce, SteadyState
from idm_rs.core.units import interval, si
from idm_rs.diagnosis.identifiability import ParamStatus


def test_si_prefixes_keep_the_significant_digits():
    assert si(2.5e-14, "m") == "25 fm"
    assert si(-2.681158e-6, "m") == "-2.681 µm"
    assert si(0.558, "N") == "558 mN" and si(1.38e-4, "m/s") == "138 µm/s"
    assert si(0.0, "m") == "0 m" and si(math.nan, "m") == "nan m"
    assert si(0.947, "") == "0.947" and si(1e12, "Hz") == "1000 GHz"


def test_an_interval_shows_the_digits_that_tell_its_ends_apart():
    assert interval(1.2381e-7, 1.2419e-7, "m") == "[123.8, 124.2] nm"
    lo, hi = interval(1.24e-7, 1.2400003e-7, "m").strip("[] nm").split(", ")
    assert lo != hi
    assert interval(0.5, 0.6) == "[0.5, 0.6]"


def test_steady_state_and_stall_force_print_their_units():
    text = str(SteadyState(-2.68e-3, -2.68e-6, 1.1e-7, 4.8e-5, 0.947, -1.0))
    assert "backward" in text and "-2.68 mm/s" in text and "-2.68 µm ± 110 nm per cycle" in text
    assert "48 µm per cycle" in text
    stall = StallForce(0.558, np.array([0.0, 1.0]), np.array([1.38e-4, -1e-4]), 1e-4, 1.0)
    assert str(stall).startswith("StallForce(558 mN ± 50 µN") and "138 µm/s" in str(stall)


def test_an_identifiability_interval_is_never_printed_as_one_number():
    ident = ParamStatus("c_weight", 1.24e-7, 1e-12, 1.24e-7 - 2e-12, 1.24e-7 + 2e-12, True)
    words = ident.words("m")
    a, b = words.split("interval [")[1].split("]")[0].split(", ")
    assert a != b, words
