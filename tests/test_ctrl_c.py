"""Ctrl-C as a user sends it: SIGINT to a separate process running a script or a command. A
library call stops and raises KeyboardInterrupt (what it finished in its `partial`) so the script stops; every
command exits 130, keeps what finished and never draws an unfinished point as a finding."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[1]


def _start(args: list[str], cwd: Path) -> subprocess.Popen[str]:
    env = dict(os.environ, PYTHONUNBUFFERED="1", OMP_NUM_THREADS="1")
    python_dir = str(ROOT / "python")
    if (ROOT / "python" / "idm_rs" / "_core.abi3.so").exists():  # a development checkout
        env["PYTHONPATH"] = python_dir + os.pathsep + env.get("PYTHONPATH", "")
    # a shell's background jobs start with SIGINT ignored and a child inherits that: restore the
    # default so that Python installs its KeyboardInterrupt handler, as in a terminal
    return subprocess.Popen([sys.executable, *args], cwd=cwd, env=env, text=True, stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))


def _interrupt(proc: subprocess.Popen[str], after: float, limit: float = 10.0) -> tuple[int, str, str, float]:
    """SIGINT ``after`` s after the process said it started (its first stdout line); (exit code,
    stdout, stderr, seconds from the signal to the exit)."""
    first = proc.stdout.readline() if proc.stdout else ""
    time.sleep(after)
    assert proc.poll() is None, "the process ended before it was interrupted"
    proc.send_signal(signal.SIGINT)
    sent = time.perf_counter()
    SIGNALLED_AT[proc.pid] = time.time()
    out, err = proc.communicate(timeout=limit)
    return proc.returncode, first + out, err, time.perf_counter() - sent


#: the wall-clock time each process was sent SIGINT [s since the epoch], by pid
SIGNALLED_AT: dict[int, float] = {}


LOOP = """
import idm_rs
print("started", flush=True)
for i in range(1000):
    r = idm_rs.simulate(idm_rs.Params(), idm_rs.Triangle(), t_end=50e-3, dt=1e-8, model="dps")
    print(i, r.final_position, flush=True)
print("ran to the end", flush=True)
"""


def test_a_script_looping_over_simulate_stops_on_ctrl_c(tmp_path):
    proc = _start(["-c", LOOP], tmp_path)
    rc, out, err, took = _interrupt(proc, after=1.5)
    assert "ran to the end" not in out
    # the uncaught KeyboardInterrupt: Python re-raises SIGINT on itself (a shell shows 130)
    assert rc in (-signal.SIGINT, 130), (rc, err[-2000:])
    # inside the engine's run the interrupt says where it stopped (and carries the trajectory);
    # between two runs it is Python's own
    assert "KeyboardInterrupt" in err.splitlines()[-1], err[-2000:]
    assert took < 3.0, f"{took:.1f} s from Ctrl-C to the end"


@pytest.mark.parametrize("after", [1.0, 3.0])
def test_reproduce_exits_130_and_draws_nothing_it_did_not_finish(tmp_path, after):
    # "started" once the package is imported: a signal inside the import (seconds on a loaded
    # machine) reaches the interpreter before the command, which is not what is tested here
    proc = _start(["-c", "from idm_rs.apps.cli import main; print('started', flush=True); raise SystemExit(main())",
                   "reproduce", "--no-progress", "--out", str(tmp_path / "figs")], tmp_path)
    rc, out, err, took = _interrupt(proc, after=after)
    assert rc == 130, (rc, err[-2000:])
    assert "error: interrupted" in err
    assert took < 3.0, f"{took:.1f} s from Ctrl-C to the end"
    # stopped before or inside the Fig. 7a sweep, it is never drawn; a quiet machine finishes that
    # sweep ~3 s in, and a figure finished before the signal is what was finished
    fig = tmp_path / "figs" / "fig7a.png"
    assert not fig.exists() or fig.stat().st_mtime < SIGNALLED_AT[proc.pid], \
        "a Fig. 7 was drawn from an interrupted sweep"
    assert "total time" not in out


def test_the_sweep_command_exits_130_and_writes_the_finished_points(tmp_path):
    xr = pytest.importorskip("xarray")
    out = tmp_path / "s.nc"
    proc = _start(["-c", "from idm_rs.apps.cli import main; print('started', flush=True); raise SystemExit(main())",
                   "sweep", "--model", "lps", "--grid", "voltage=40:120:2000", "--t-end", "0.002", "--dt", "1e-8",
                   "--method", "rk4", "--threads", "1", "--no-progress", "--out", str(out)], tmp_path)
    rc, stdout, err, took = _interrupt(proc, after=6.0, limit=20.0)
    assert rc == 130, (rc, err[-2000:])
    assert took < 5.0, f"{took:.1f} s from Ctrl-C to the end"
    with xr.open_dataset(out) as ds:
        status = ds["status"].values
        assert ds.attrs["complete"] == 0
        assert 0 < (status == 1).sum() < status.size and set(status.tolist()) <= {0, 1}


def test_ctrl_c_outside_the_engine_call_of_a_piece_keeps_what_finished(monkeypatch):
    """A simulate run with a progress bar runs in pieces; Ctrl-C landing in the Python around a
    piece's engine call (no trajectory on the stop) gave an IndexError on the first piece (seen
    on a loaded machine); it must be a KeyboardInterrupt whose partial is the pieces finished."""
    import idm_rs
    from idm_rs.core import simulation

    real = simulation.engine.simulate
    calls = []
    stop = {"at": 0}  # the engine call (1-based) that Ctrl-C lands beside

    def stopping(*a, **k):
        calls.append(1)
        if len(calls) == stop["at"]:
            raise KeyboardInterrupt
        return real(*a, **k)

    monkeypatch.setattr(simulation.engine, "simulate", stopping)
    wave = idm_rs.Triangle(amplitude=80.0, rise=0.5e-3, fall=1e-5)
    for at, finished in ((1, False), (3, True)):
        calls.clear()
        stop["at"] = at
        with pytest.raises(KeyboardInterrupt) as e:
            idm_rs.simulate(idm_rs.Params(), wave, t_end=2e-3, dt=1e-8, save_every=100, progress=True)
        partial = idm_rs.partial_result(e.value)
        if not finished:
            assert partial is None
        else:
            # the two pieces before the stop, joined: saved every 1e-6 s from 0 to their end
            assert partial is not None and partial.t[0] == 0.0 and partial.t.size > 2
            assert np.all(np.diff(partial.t) > 0)


def test_a_ctrl_c_as_the_run_ends_keeps_the_whole_run(monkeypatch):
    """A Ctrl-C that comes as the engine's run ends (after its last look for one) is taken by the
    engine and reported beside the run (``interrupted``), and one that lands in the Python that
    builds the result is caught there: either way the KeyboardInterrupt carries the whole,
    complete result, equal to the run's (before, the run was lost)."""
    import idm_rs
    from idm_rs.core import simulation

    kw = dict(t_end=1e-3, model="lps", method="auto")
    whole = idm_rs.simulate(idm_rs.Params(), idm_rs.Triangle(), **kw)
    real = simulation.engine.simulate
    monkeypatch.setattr(simulation.engine, "simulate", lambda *a: {**real(*a), "interrupted": True})
    with pytest.raises(KeyboardInterrupt, match="as its run ended") as stop:
        idm_rs.simulate(idm_rs.Params(), idm_rs.Triangle(), **kw)
    kept = idm_rs.partial_result(stop.value)
    assert kept.complete and kept.final_position == whole.final_position
    monkeypatch.setattr(simulation.engine, "simulate", real)
    build, calls = simulation._result_of, []

    def interrupted_once(*a):
        calls.append(1)
        if len(calls) == 1:
            raise KeyboardInterrupt
        return build(*a)

    monkeypatch.setattr(simulation, "_result_of", interrupted_once)
    with pytest.raises(KeyboardInterrupt, match="after its run reached") as stop:
        idm_rs.simulate(idm_rs.Params(), idm_rs.Triangle(), **kw)
    kept = idm_rs.partial_result(stop.value)
    assert kept.complete and kept.final_position == whole.final_position


def test_a_ctrl_c_as_a_piece_of_a_long_run_ends_keeps_the_pieces_as_incomplete(monkeypatch):
    """A run with a progress bar goes in pieces; a Ctrl-C as the second piece ends keeps that
    piece whole, but the run is not: the kept result ends there and says it is incomplete (before,
    the CLI printed it as the final position with exit code 0)."""
    import idm_rs
    from idm_rs.core import simulation

    real, calls = simulation.engine.simulate, []

    def second_piece_interrupted(*a):
        calls.append(1)
        out = real(*a)
        return {**out, "interrupted": True} if len(calls) == 2 else out

    monkeypatch.setattr(simulation.engine, "simulate", second_piece_interrupted)
    with pytest.raises(KeyboardInterrupt) as stop:
        idm_rs.simulate(idm_rs.Params(), idm_rs.Triangle(), t_end=1e-3, dt=1e-8, model="lps", save_every=100,
                        progress=True)
    kept = idm_rs.partial_result(stop.value)
    assert len(calls) == 2 and not kept.complete
    assert 0 < kept.t[-1] < 1e-3


FINALIZER = """
import contextlib, signal, sys, time
from idm_rs.apps.cli_interrupts import interrupts_not_swallowed

class InterruptedAsItIsCollected:
    def __del__(self):
        signal.raise_signal(signal.SIGINT)

with interrupts_not_swallowed() if sys.argv[1] == "command" else contextlib.nullcontext():
    obj = InterruptedAsItIsCollected()
    del obj
    start = time.perf_counter()
    while time.perf_counter() - start < 2.0:
        time.sleep(0.005)
print("ran to the end", flush=True)
"""


@pytest.mark.parametrize("handler", ["python", "command"])
def test_a_commands_ctrl_c_inside_a_finalizer_is_raised_after_it(tmp_path, handler):
    """A Ctrl-C that Python's own handler raises inside a finalizer or weakref callback is printed
    as "Exception ignored" and lost (CI saw `reproduce` run to its end and exit 0 so); a command's
    handler moves it out of there, into the command's own code."""
    proc = _start(["-c", FINALIZER, handler], tmp_path)
    out, err = proc.communicate(timeout=20)
    if handler == "python":
        assert proc.returncode == 0 and "ran to the end" in out and "Exception ignored" in err
    else:
        assert proc.returncode in (-signal.SIGINT, 130), (proc.returncode, err[-2000:])
        assert "ran to the end" not in out and "Exception ignored" not in err
        assert "KeyboardInterrupt" in err.splitlines()[-1]


def test_a_handler_the_caller_set_is_left_as_it_is():
    from idm_rs.apps.cli_interrupts import interrupts_not_swallowed

    seen: list[int] = []
    previous = signal.signal(signal.SIGINT, lambda *a: seen.append(1))
    try:
        with interrupts_not_swallowed():
            signal.raise_signal(signal.SIGINT)
            assert signal.getsignal(signal.SIGINT) is not signal.default_int_handler
    finally:
        signal.signal(signal.SIGINT, previous)
    assert seen == [1]
