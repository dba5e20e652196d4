"""One validation for the options the long calls share: every bad count, thread number, retry
count or start-up cycle count is refused by name before anything runs, the same way in
`simulate`, `sweep`, `characterize`, `steady_state` and the CLI — never run as nothing and
reported complete, never an OverflowError from deep inside, never NaN metrics called "ok"."""

from __future__ import annotations

import math

import pytest

import idm_rs
from idm_rs.apps.actuator import characterize
from idm_rs.apps.cli import main
from idm_rs.core import options

P = idm_rs.Params()
TRAIN = idm_rs.Sawtooth(amplitude=80.0, frequency=500.0, cycles=3)


@pytest.mark.parametrize("kw, words", [
    (dict(block_size=-5), "parameter 'block_size' must be a positive integer, got -5"),
    (dict(block_size=0), "parameter 'block_size' must be a positive integer, got 0"),
    (dict(threads=-1), "parameter 'threads' must be a positive integer or None (every core), got -1"),
    (dict(threads=0), "parameter 'threads' must be a positive integer or None"),
    (dict(threads=2.5), "parameter 'threads' must be a positive integer or None"),
    (dict(retries=-1), "parameter 'retries' must be an integer >= 0, got -1"),
    (dict(retries=math.inf), "parameter 'retries' must be an integer >= 0, got inf"),
    (dict(skip_cycles=3), "the train has 3 cycles and skip_cycles = 3 skips them all"),
    (dict(skip_cycles=-1), "parameter 'skip_cycles' must be an integer >= 0, got -1"),
    (dict(n_elements=0), "parameter 'n_elements' must be a positive integer, got 0"),
])
def test_sweep_refuses_a_bad_option_by_name(kw, words):
    with pytest.raises(ValueError) as err:
        idm_rs.sweep(P, TRAIN, {"voltage": [60.0, 80.0]}, model="lps", progress=False, **kw)
    assert words in str(err.value)


def test_a_swept_cycle_count_is_checked_against_skip_cycles():
    with pytest.raises(ValueError, match="the train has 2 cycles and skip_cycles = 2 skips them all"):
        idm_rs.sweep(P, TRAIN, {"cycles": [2, 5]}, model="lps", progress=False)


def test_the_same_words_in_every_call():
    """steady_state, characterize and sweep share one check (a triangle has no cycles to skip)."""
    r = idm_rs.simulate(P, TRAIN, t_end=TRAIN.duration, model="lps", method="auto")
    words = "the train has 3 cycles and skip_cycles = 3 skips them all"
    with pytest.raises(ValueError, match=words):
        r.steady_state(skip_cycles=3)
    with pytest.raises(ValueError, match=words):
        characterize(P, model="lps", cycles=3, skip_cycles=3, progress=False)
    with pytest.raises(ValueError, match="parameter 'threads' must be a positive integer or None"):
        characterize(P, model="lps", threads=0, progress=False)
    with pytest.raises(ValueError, match="parameter 'save_every' must be a positive integer, got 0"):
        idm_rs.simulate(P, TRAIN, t_end=1e-4, model="lps", save_every=0)
    assert options.skip_cycles(0, None) == 0 and options.count("k", 3.0) == 3


def test_the_sweep_command_refuses_skipping_every_cycle(capsys, tmp_path):
    """Before: "status: ok", exit 0 and an empty plot for NaN steady-state metrics."""
    plot = tmp_path / "v.png"
    rc = main(["sweep", "--model", "lps", "--waveform", "sawtooth", "--cycles", "3", "--skip-cycles", "3",
               "--grid", "voltage=60,80", "--metric", "mean_velocity", "--plot", str(plot), "--no-progress"])
    cap = capsys.readouterr()
    assert rc == 2 and "skips them all" in cap.err and "status: ok" not in cap.out
    assert not plot.exists()
    rc = main(["sweep", "--model", "lps", "--grid", "voltage=60,80", "--retries", "-1", "--no-progress"])
    assert rc == 2 and "parameter 'retries' must be an integer >= 0, got -1" in capsys.readouterr().err
