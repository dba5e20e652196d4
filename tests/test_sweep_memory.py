"""Sweeps and memory: a grid whose results cannot fit is refused up front with what it needs,
and ``out=...zarr`` writes the results block by block so a sweep larger than memory runs."""

import importlib

import numpy as np
import pytest

import idm_rs
from idm_rs.cli import main

sweep_module = importlib.import_module("idm_rs.sweep")

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
    assert stored.chunks["m2"] == (2, 2, 1)  # three slabs of the first axis
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
    real, calls = sweep_module._run_local, []

    def stop_on_the_second(*args, **kw):
        calls.append(1)
        if len(calls) == 2:
            raise KeyboardInterrupt
        return real(*args, **kw)

    monkeypatch.setattr(sweep_module, "_run_local", stop_on_the_second)
    with pytest.raises(KeyboardInterrupt, match="6 of 15 points written") as stop:
        idm_rs.sweep(idm_rs.Params(), idm_rs.Triangle(), GRID, model="lps", method="auto", progress=False,
                     out=tmp_path / "s.zarr", block_size=6)
    ds = idm_rs.partial_result(stop.value)
    assert ds.attrs["complete"] == 0
    status = ds["status"].values
    assert (status[:2] == 1).all() and (status[2:] == 0).all()
    assert np.isfinite(ds["final_position"].values[:2]).all() and np.isnan(ds["final_position"].values[2:]).all()
