"""Sweeps and memory: a grid whose results cannot fit is refused up front with what it needs,
and ``out=...zarr`` writes the results block by block so a sweep larger than memory runs."""

import importlib

import numpy as np
import pytest

import idm_rs
from idm_rs.apps.cli import main

sweep_module = importlib.import_module("idm_rs.sweeps.sweep")

pytest.importorskip("zarr")

GRID = {"m2": np.linspace(0.1, 0.5, 5), "voltage": [60.0, 80.0, 100.0]}


def test_a_grid_too_large_for_memory_is_refused_up_front_with_what_it_needs(monkeypatch, capsys):
    monkeypatch.setattr(sweep_module, "_available_memory", lambda: 2**30)  # 1 GiB
    with pytest.raises(MemoryError, match=r"100,000,000 points needs 11.3 GiB .* 1.0 GiB .* out='sweep.zarr'"):
        idm_rs.sweep(idm_rs.Params(), idm_rs.Triangle(), {"m2": np.linspace(0.1, 0.5, 10_000),
                                                          "voltage": np.linspace(40, 120, 10_000)}, progress=False)
    code = main(["sweep", "--model", "lps", "--grid", "m2=0.1:0.5:100000", "--grid", "voltage=40:120:100000",
                 "--no-progress"])
    assert code == 2 and "GiB for its results" in capsys.readouterr().err


def test_a_store_written_block_by_block_holds_what_memory_holds(tmp_path):
    whole = idm_rs.sweep(idm_rs.Params(), idm_rs.Triangle(), GRID, model="lps", method="auto", progress=False)
    stored = idm_rs.sweep(idm_rs.Params(), idm_rs.Triangle(), GRID, model="lps", method="auto", progress=False,
                          out=tmp_path / "s.zarr", block_size=6)
    assert stored["status"].encoding["chunks"] == (2, 3)  # three slabs of the first axis
    assert stored.attrs["complete"] == 1 and stored.attrs["points_finished"] == 15
    for name in whole.data_vars:
        a, b = whole[name].values, stored[name].values
        if name == "reason":
            assert list(map(str, a.ravel())) == list(map(str, b.ravel()))
        else:
            assert np.array_equal(a, b, equal_nan=a.dtype.kind == "f"), name
    with pytest.raises(ValueError, match="exists; remove it"):
        idm_rs.sweep(idm_rs.Params(), idm_rs.Triangle(), GRID, model="lps", progress=False, out=tmp_path / "s.zarr")
    with pytest.raises(ValueError, match="must name a Zarr store"):
        idm_rs.sweep(idm_rs.Params(), idm_rs.Triangle(), GRID, model="lps", progress=False, out=tmp_path / "s.nc")


def test_an_interrupted_store_keeps_the_slabs_it_wrote(tmp_path, monkeypatch):
    from idm_rs.sweeps.backends import LocalEngine

    real, calls = LocalEngine.run, []

    def stop_on_the_second(*args, **kw):
        calls.append(1)
        if len(calls) == 2:
            raise KeyboardInterrupt
        return real(*args, **kw)

    monkeypatch.setattr(LocalEngine, "run", stop_on_the_second)
    with pytest.raises(KeyboardInterrupt, match="6 of 15 points written") as stop:
        idm_rs.sweep(idm_rs.Params(), idm_rs.Triangle(), GRID, model="lps", method="auto", progress=False,
                     out=tmp_path / "s.zarr", block_size=6)
    ds = idm_rs.partial_result(stop.value)
    assert ds.attrs["complete"] == 0
    status = ds["status"].values
    assert (status[:2] == 1).all() and (status[2:] == 0).all()
    assert np.isfinite(ds["final_position"].values[:2]).all() and np.isnan(ds["final_position"].values[2:]).all()


def test_a_1e8_grid_runs_into_a_store_in_bounded_memory_and_stops_on_ctrl_c(tmp_path):
    """The route the out-of-memory message recommends, at scale: 10^8 points (results 11 GiB in
    memory) into a Zarr store from a separate process. The store is laid out from the axes alone
    and written slab by slab: the first slab's estimate of the run time is printed, Ctrl-C stops
    it within seconds with exit 130 and the slabs kept, and the process never holds more than a
    few hundred MB (before: 2.25 GB for the layout, 15 s to stop; at 10^10 points 20 GB and a
    crash)."""
    import os
    import signal
    import subprocess
    import sys
    import time
    from pathlib import Path

    import xarray as xr

    root = Path(__file__).resolve().parents[1]
    env = dict(os.environ, PYTHONUNBUFFERED="1", OMP_NUM_THREADS="1")
    if (root / "python" / "idm_rs" / "_core.abi3.so").exists():
        env["PYTHONPATH"] = str(root / "python") + os.pathsep + env.get("PYTHONPATH", "")
    store = tmp_path / "big.zarr"
    out_file = (tmp_path / "stdout.txt").open("w")
    proc = subprocess.Popen(
        [sys.executable, "-c", "from idm_rs.apps.cli import main; raise SystemExit(main())", "sweep", "--model", "lps",
         "--grid", "m2=0.1:0.5:10000", "--grid", "voltage=40:120:10000", "--t-end", "2e-4", "--method", "auto",
         "--threads", "1", "--no-progress", "--out", str(store)],
        env=env, text=True, stdout=out_file, stderr=subprocess.PIPE,
        preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))
    said = ""
    deadline = time.perf_counter() + 240
    while "takes about" not in said and time.perf_counter() < deadline:  # the first slab's estimate
        line = proc.stderr.readline()
        if not line:
            break
        said += line
    assert "this sweep of 100,000,000 points takes about" in said, said
    proc.send_signal(signal.SIGINT)
    sent = time.perf_counter()
    err = proc.stderr.read()  # to the end: the process has exited or closed it
    _, status, usage = os.wait4(proc.pid, 0)  # this process's own peak, not every child's of the test run
    took = time.perf_counter() - sent
    out_file.close()
    proc.stderr.close()
    proc.returncode = os.waitstatus_to_exitcode(status)  # reaped here: Popen must not wait again
    peak_mb = usage.ru_maxrss / 1024
    assert proc.returncode == 130, err[-2000:]
    # 5 s on a machine with a core per runnable process; a loaded one (benches beside the suite)
    # stretches every wall-clock figure by its load per core
    stretch = max(1.0, os.getloadavg()[0] / (os.cpu_count() or 1))
    assert took < 5.0 * stretch, f"{took:.1f} s from Ctrl-C to the end (load {os.getloadavg()[0]:.1f})"
    assert peak_mb < 800, f"the sweep process peaked at {peak_mb:.0f} MB"
    ds = xr.open_zarr(store, consolidated=False, chunks=None)
    assert ds.attrs["complete"] == 0 and ds["status"].shape == (10_000, 10_000)
    written = int(ds.attrs["points_finished"])
    assert written >= 60_000 and (ds["status"].values[:6] == 1).all()
    assert (ds["status"][-1, -5:].values == 0).all()
