"""The Examples sections of the public docstrings run and print what they say (doctest)."""

from __future__ import annotations

import doctest

import pytest

import idm_rs
from idm_rs.apps.actuator import characterize, stall_force, steady_state
from idm_rs.io.synthetic import make_case
from idm_rs.rigs import diagnose_rig, rig_fit


@pytest.mark.parametrize("obj", [idm_rs.simulate, idm_rs.sweep, idm_rs.diagnose, characterize, steady_state,
                                 stall_force, diagnose_rig, idm_rs.partial_result, idm_rs.Triangle,
                                 idm_rs.Sawtooth, idm_rs.Sampled, make_case, rig_fit, idm_rs.text_report,
                                 idm_rs.plot_diagnosis, idm_rs.load_case], ids=lambda o: o.__name__)
def test_the_examples_run(obj):
    finder = doctest.DocTestFinder(recurse=False)
    runner = doctest.DocTestRunner(optionflags=doctest.ELLIPSIS | doctest.NORMALIZE_WHITESPACE)
    tests = finder.find(obj, globs={"idm_rs": idm_rs})
    for t in tests:
        runner.run(t)
    assert runner.failures == 0
