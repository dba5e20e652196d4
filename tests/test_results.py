"""The SimulationResult object: saved times, views on the state, and the xarray export."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

import idm_rs
from idm_rs.core.waveforms import voltage_at

WAVE = idm_rs.Triangle(amplitude=80.0, rise=0.3e-3, fall=0.5e-3)


@pytest.fixture(scope="module", params=["lps", "dps"])
def result(request) -> idm_rs.SimulationResult:
    return idm_rs.simulate(
        idm_rs.Params(m1=0.35), WAVE, 1e-3, 1e-8, model=request.param, n_elements=3, save_every=300, energy=True
    )


# --------------------------------------------------------------------------------------------
# saved times and views
# --------------------------------------------------------------------------------------------
@given(
    t_end=st.integers(1, 40).map(lambda k: k * 1e-5),
    dt=st.sampled_from([1e-8, 2e-8, 5e-8]),
    save_every=st.integers(1, 700),
)
def test_saved_times_are_multiples_of_save_every_dt_plus_t_end(t_end, dt, save_every):
    r = idm_rs.simulate(idm_rs.Params(), WAVE, t_end, dt, model="lps", save_every=save_every)
    steps = round(t_end / dt)
    k = np.arange(0, steps + 1, save_every)
    expected = k * dt  # the core computes t = (step index) * dt
    if k[-1] != steps:
        expected = np.append(expected, steps * dt)
    np.testing.assert_array_equal(r.t, expected)
    assert r.t[-1] == pytest.approx(t_end, rel=1e-12)
    assert np.all(np.diff(r.t) > 0)  # t_end is not saved twice
    n = r.t.size
    for name in ("friction", "fh", "g", "h", "voltage", "piezo_force", "reading"):
        assert getattr(r, name).shape == (n,), name
    assert r.nodes.shape == r.velocities.shape == (n, 2)


def test_views_on_the_state(result):
    r = result
    np.testing.assert_array_equal(r.main_body, r.nodes[:, 0])
    np.testing.assert_array_equal(r.weight, r.nodes[:, -1])
    np.testing.assert_array_equal(r.main_body_velocity, r.velocities[:, 0])
    assert r.final_position == r.main_body[-1] == r.final_state[0]
    np.testing.assert_array_equal(r.reading, r.main_body)  # no sensor effect
    assert r.nodes.shape[1] == (2 if r.model == "lps" else r.n_elements + 1)
    assert abs(r.final_position) > 1e-8  # it moved


def test_saved_voltage_and_piezo_force_follow_the_input(result):
    """V at the saved times is the waveform's value; Fp = kp (d33 V - h) (MODEL.md eq. 14)."""
    r = result
    p = r.params
    np.testing.assert_allclose(r.voltage, voltage_at(WAVE, r.t), rtol=0, atol=1e-11)
    np.testing.assert_allclose(r.piezo_force, p.kp * (p.d33 * r.voltage - r.h), rtol=1e-12, atol=1e-9)


# --------------------------------------------------------------------------------------------
# xarray
# --------------------------------------------------------------------------------------------
def test_to_xarray_has_units_on_every_variable(result):
    ds = result.to_xarray()
    assert set(ds.data_vars) >= {"main_body", "weight", "nodes", "velocities", "friction", "fh", "g", "h",
                                 "voltage", "piezo_force", "reading"}
    for name, var in ds.data_vars.items():
        assert var.attrs.get("units"), f"data variable {name!r} has no units"
    units = {k: ds[k].attrs["units"] for k in ds.data_vars}
    assert units["main_body"] == units["nodes"] == units["g"] == units["h"] == "m"
    assert units["velocities"] == "m/s" and units["voltage"] == "V"
    assert units["friction"] == units["fh"] == units["piezo_force"] == "N"
    assert ds["time"].attrs["units"] == "s"
    np.testing.assert_array_equal(ds["time"].values, result.t)
    np.testing.assert_array_equal(ds["main_body"].values, result.main_body)


def test_to_xarray_has_units_on_every_coordinate(result):
    ds = result.to_xarray()
    for name, coord in ds.coords.items():
        assert "units" in coord.attrs, f"coordinate {name!r} has no units"


def test_to_xarray_attrs_carry_every_parameter_and_dt(result):
    ds = result.to_xarray()
    resolved = result.params.to_dict()
    for f in dataclasses.fields(idm_rs.Params):
        assert f"param_{f.name}" in ds.attrs, f"attrs lack parameter {f.name}"
        assert ds.attrs[f"param_{f.name}"] == resolved[f.name]
        assert ds.attrs.get(f"param_{f.name}_units"), f"attrs lack units of {f.name}"
    assert ds.attrs["param_m1"] == 0.35
    assert ds.attrs["param_normal_force"] == pytest.approx(result.params.effective_normal_force, rel=1e-15)
    assert ds.attrs["dt_s"] == result.dt == 1e-8
    assert ds.attrs["model"] == result.model
    assert ds.attrs["n_elements"] == result.n_elements
    assert ds.attrs["piezo_hysteresis"] == 1
    assert ds.attrs["final_position_m"] == result.final_position
    assert "Triangle" in ds.attrs["waveform"]


def test_to_xarray_round_trips_through_netcdf(result, tmp_path):
    pytest.importorskip("netCDF4")
    import xarray as xr

    path = tmp_path / "run.nc"
    result.to_xarray().to_netcdf(path)
    with xr.open_dataset(path) as back:
        np.testing.assert_array_equal(back["nodes"].values, result.nodes)
        assert back.attrs["dt_s"] == result.dt
        assert back["main_body"].attrs["units"] == "m"
