"""``idm_rs.sweep``: point-by-point equality with ``simulate``, labelled dimensions, bitwise
determinism across threads and blocks, Ctrl-C, the Dask path, divergence handling, dopri5, and
input errors. Runs are short (LPS, 1-2 ms) so the whole file takes a few seconds."""

from __future__ import annotations

import importlib
import math
import time
import warnings
from dataclasses import fields

import numpy as np
import pytest
import xarray  # noqa: F401  (imported here so that the Ctrl-C test does not interrupt an import)

import idm_rs
from conftest import interrupt_main_when
from idm_rs.sweeps.sweep import METRICS

P = idm_rs.Params()
WAVE = idm_rs.Triangle(80.0, 0.5e-3, 9.5e-3)
SHORT_WAVE = idm_rs.Triangle(80.0, 0.3e-3, 0.7e-3)  # up and back down within 1 ms
OUTPUTS = (*METRICS, "status", "diverged_at", "dt_used", "steps")


def point_case(params: idm_rs.Params, waveform, effects: dict, axis: str, v: float):
    """(params, waveform, effects) of one grid value, built the way the documentation defines
    each axis: mass_ratio m2 = r m1; pe_mass_ratio rho_p = r m1 / (Ap l); stiffness
    Ep = kp l / Ap; voltage = amplitude; any other name is a Params, waveform or Effects field."""
    import dataclasses

    if axis == "mass_ratio":
        return params.replace(m2=v * params.m1), waveform, effects
    if axis == "pe_mass_ratio":
        return params.replace(pe_density=v * params.m1 / (params.pe_area * params.pe_length)), waveform, effects
    if axis == "stiffness":
        return params.replace(pe_youngs=v * params.pe_length / params.pe_area), waveform, effects
    if axis in ("voltage", "amplitude"):
        return params, dataclasses.replace(waveform, amplitude=v), effects
    if axis in {f.name for f in fields(idm_rs.Params)}:
        return params.replace(**{axis: v}), waveform, effects
    if axis in {f.name for f in fields(idm_rs.Effects)}:
        return params, waveform, {**effects, axis: v}
    return params, dataclasses.replace(waveform, **{axis: v}), effects


def simulate_point(ds, index: tuple[int, ...], params, waveform, *, t_end, dt, model, n_elements=4, **kw):
    """``simulate()`` of the grid point at ``index`` of ``ds`` (dims in order)."""
    effects: dict = {}
    for axis, i in zip(ds.final_position.dims, index):
        params, waveform, effects = point_case(params, waveform, effects, axis, float(ds[axis].values[i]))
    return idm_rs.simulate(params, waveform, t_end, dt, model=model, n_elements=n_elements,
                           effects=idm_rs.Effects(**effects), **kw)


# --- equality with simulate() -------------------------------------------------------------------

EQUALITY_CASES = [
    pytest.param("lps", {"mass_ratio": [0.25, 1.0, 2.0], "voltage": [40.0, 120.0]}, P, id="lps-mass_ratio-voltage"),
    pytest.param("lps", {"stiffness": [1.5e7, 4e7], "pe_mass_ratio": [0.02, 0.2], "mu_k": [0.4]}, P,
                 id="lps-stiffness-pe_mass_ratio-mu_k"),
    pytest.param("dps", {"pe_mass_ratio": [0.05, 0.2], "rise": [0.2e-3, 0.3e-3]}, P, id="dps2-pe_mass_ratio-rise"),
    pytest.param("lps", {"mass_ratio": [0.5, 1.5], "c_weight": [0.0, 2.0]}, P.replace(normal_force=5.0),
                 id="lps-fixed-normal-force-effect"),
]


@pytest.mark.parametrize("model, grid, params", EQUALITY_CASES)
def test_sweep_equals_simulate_point_by_point(model, grid, params):
    t_end, dt, n = 1e-3, 2e-8, 2
    ds = idm_rs.sweep(params, SHORT_WAVE, grid, t_end=t_end, dt=dt, model=model, n_elements=n,
                      method="rk4", progress=False, threads=2)
    assert ds.attrs["complete"] == 1
    assert (ds.status.values == 1).all()
    for index in np.ndindex(ds.final_position.shape):
        r = simulate_point(ds, index, params, SHORT_WAVE, t_end=t_end, dt=dt, model=model, n_elements=n,
                           save_every=1)
        point = ds.isel(dict(zip(ds.final_position.dims, index)))
        # the normal force follows the swept masses unless it is set
        q = r.params
        resolved = q.to_dict(resolved=True)["normal_force"]
        if params.normal_force is None:
            from idm_rs.core.declarations import GRAVITY

            assert resolved == pytest.approx((q.m1 + q.m2 + q.pe_density * q.pe_area * q.pe_length) * GRAVITY,
                                             rel=1e-12), index
        else:
            assert resolved == params.normal_force, index
        assert float(point.final_position) == r.final_position, index
        assert float(point.peak_velocity) == float(np.max(np.abs(r.main_body_velocity))), index
        assert int(point.steps) == round(t_end / dt)
        assert float(point.dt_used) == dt
        assert math.isnan(float(point.diverged_at))


def test_derived_normal_force_changes_with_mass_ratio():
    """A swept weight changes the friction through the normal force: a sweep with the normal
    force fixed at the paper case's value differs from the derived one away from m2/m1 = 0.75."""
    grid = {"mass_ratio": [0.25, 0.75]}
    kw = dict(t_end=1e-3, dt=2e-8, model="lps", progress=False)
    derived = idm_rs.sweep(P, SHORT_WAVE, grid, **kw)
    fixed = idm_rs.sweep(P.replace(normal_force=P.effective_normal_force), SHORT_WAVE, grid, **kw)
    assert float(derived.final_position[1]) == float(fixed.final_position[1])
    assert float(derived.final_position[0]) != float(fixed.final_position[0])
    assert derived.attrs["normal_force_rule"] != fixed.attrs["normal_force_rule"]


# --- labels -------------------------------------------------------------------------------------


def test_dimensions_follow_grid_order_with_units():
    grid = {"voltage": [60.0, 100.0], "mass_ratio": [0.5, 1.0, 1.5], "mu_k": [0.45, 0.5]}
    params = P.replace(normal_force=7.0)
    ds = idm_rs.sweep(params, SHORT_WAVE, grid, t_end=1e-3, dt=5e-8, model="lps", progress=False)
    assert tuple(ds.final_position.dims) == ("voltage", "mass_ratio", "mu_k")
    assert ds.final_position.shape == (2, 3, 2)
    for name, values in grid.items():
        np.testing.assert_array_equal(ds[name].values, values)
    assert ds["voltage"].attrs["units"] == "V"
    assert ds["mass_ratio"].attrs["units"] == "1"
    assert ds["mu_k"].attrs["units"] == "1"
    for name in grid:
        assert ds[name].attrs["long_name"]
    for name in (*METRICS, "status", "diverged_at", "dt_used", "steps"):
        assert name in ds.data_vars
        assert tuple(ds[name].dims) == ("voltage", "mass_ratio", "mu_k")
        assert ds[name].attrs["long_name"]
    for name, (units, _) in METRICS.items():
        assert ds[name].attrs["units"] == units
    assert ds.final_position.attrs["units"] == "m"
    assert ds.diverged_at.attrs["units"] == "s" and ds.dt_used.attrs["units"] == "s"
    assert "flag_meanings" in ds.status.attrs

    a = ds.attrs
    assert a["idm_rs_version"] == idm_rs.__version__
    for f in fields(idm_rs.Params):
        assert a[f"param_{f.name}"] == getattr(params, f.name), f.name
    assert a["dt_s"] == 5e-8
    assert a["t_end_s"] == 1e-3
    assert a["method"] == "rk4"
    assert a["model"] == "lps"
    assert a["waveform"] == repr(SHORT_WAVE)
    assert a["complete"] == 1


def test_derived_normal_force_is_recorded_in_attrs():
    ds = idm_rs.sweep(P, SHORT_WAVE, {"mass_ratio": [0.5]}, t_end=1e-3, dt=5e-8, model="lps", progress=False)
    for f in fields(idm_rs.Params):
        if f.name != "normal_force":
            assert ds.attrs[f"param_{f.name}"] == getattr(P, f.name)
    assert "(m1+m2+mPE)" in ds.attrs["normal_force_rule"]


# --- determinism --------------------------------------------------------------------------------


@pytest.mark.parametrize("method", ["rk4", "dopri5", "rodas4"])
def test_results_bitwise_identical_across_thread_counts(method):
    # includes a point that diverges at this dt and is retried (m2/m1 = 2 at 120 V)
    grid = {"mass_ratio": [0.25, 0.8, 2.0], "voltage": [40.0, 90.0, 120.0]}
    kw = dict(t_end=2e-3, dt=1e-7, model="lps", method=method, progress=False)
    runs = [
        idm_rs.sweep(P, WAVE, grid, threads=1, **kw),
        idm_rs.sweep(P, WAVE, grid, threads=2, **kw),
        idm_rs.sweep(P, WAVE, grid, threads=2, block_size=3, **kw),
        idm_rs.sweep(P, WAVE, grid, threads=1, block_size=2, **kw),
    ]
    if method == "rk4":
        assert (runs[0].status.values == 2).any(), "expected a retried point in the grid"
    for ds in runs[1:]:
        for name in OUTPUTS:
            assert ds[name].values.tobytes() == runs[0][name].values.tobytes(), name


# --- Ctrl-C ---------------------------------------------------------------------------------------


def test_interrupted_sweep_keeps_finished_points(monkeypatch):
    # 1,024 points x 10^6 steps: ~15 s on 2 threads with vector lanes (~33 ns per point-step).
    # Ctrl-C once the first block has finished points (not after a fixed time: on a loaded
    # machine a timer can fire before any point is done, see interrupt_main_when)
    grid = {"mass_ratio": np.linspace(0.5, 1.5, 32), "voltage": np.linspace(60.0, 100.0, 32)}
    kw = dict(t_end=20e-3, dt=2e-8, model="lps", progress=False)
    runs = []
    module = importlib.import_module("idm_rs.sweeps.backends")
    start = module.start_block

    def recording_start(*args):
        runs.append(start(*args))
        return runs[-1]

    monkeypatch.setattr(module, "start_block", recording_start)
    interrupter = interrupt_main_when(lambda: bool(runs) and runs[0].progress() > 0)
    with pytest.raises(KeyboardInterrupt, match="points finished") as stop:  # a script stops there
        idm_rs.sweep(P, WAVE, grid, threads=2, block_size=64, **kw)
    stopped = time.perf_counter()
    ds = idm_rs.partial_result(stop.value)
    interrupter.join()
    assert len(runs) < 1024 // 64, "the sweep ran to the end: the interrupt came too late"
    assert stopped - interrupter.sent_at < 1.5, f"the sweep took {stopped - interrupter.sent_at:.1f} s to stop"
    assert ds.attrs["complete"] == 0
    status = ds.status.values
    done = status == 1
    assert 0 < done.sum() < status.size
    assert set(np.unique(status)) <= {0, 1}
    for name in ("final_position", "peak_velocity", "peak_friction", "slip_fraction"):
        assert np.isfinite(ds[name].values[done]).all(), name
        assert np.isnan(ds[name].values[~done]).all(), name
    assert (ds.steps.values[~done] == 0).all()
    # the finished points are the same as a fresh run of them (a few of them: each is 0.1 s)
    for index in list(zip(*np.nonzero(done)))[:3]:
        r = simulate_point(ds, index, P, WAVE, t_end=kw["t_end"], dt=kw["dt"], model="lps", save_every=10**6)
        assert float(ds.final_position.values[index]) == r.final_position


# --- Dask -----------------------------------------------------------------------------------------


def test_dask_path_equals_local_path():
    distributed = pytest.importorskip("dask.distributed")
    grid = {"mass_ratio": [0.25, 0.75, 1.5, 2.0], "voltage": [40.0, 80.0, 100.0, 110.0, 120.0]}
    kw = dict(t_end=1e-3, dt=1e-7, model="lps", progress=False, block_size=4)
    local = idm_rs.sweep(P, WAVE, grid, **kw)
    with warnings.catch_warnings():
        # the cluster's own start-up/shut-down chatter (ports, event loops) is not under test
        warnings.simplefilter("ignore")
        with distributed.LocalCluster(n_workers=1, threads_per_worker=2, processes=True,
                                      dashboard_address=None) as cluster, distributed.Client(cluster) as client:
            remote = idm_rs.sweep(P, WAVE, grid, client=client, **kw)
    assert remote.attrs["complete"] == 1
    assert remote.attrs["executor"] == "dask"
    for name in OUTPUTS:
        assert remote[name].values.tobytes() == local[name].values.tobytes(), name
    for name in grid:
        np.testing.assert_array_equal(remote[name].values, local[name].values)


# --- divergence -----------------------------------------------------------------------------------


def test_diverging_point_is_flagged_not_poisoning():
    grid = {"mass_ratio": [0.25, 1.0], "voltage": [120.0]}
    kw = dict(t_end=2e-3, dt=4e-7, model="lps", progress=False)
    ds = idm_rs.sweep(P, WAVE, grid, retries=0, **kw)
    assert ds.attrs["complete"] == 1
    bad, good = (0, 0), (1, 0)
    assert int(ds.status.values[bad]) == 3
    t_div = float(ds.diverged_at.values[bad])
    assert 0 < t_div <= kw["t_end"]
    for name in METRICS:
        assert math.isnan(float(ds[name].values[bad])), name
    assert int(ds.status.values[good]) == 1
    r = simulate_point(ds, good, P, WAVE, t_end=kw["t_end"], dt=kw["dt"], model="lps", save_every=1)
    assert float(ds.final_position.values[good]) == r.final_position
    assert float(ds.peak_velocity.values[good]) == float(np.max(np.abs(r.main_body_velocity)))
    assert math.isnan(float(ds.diverged_at.values[good]))
    # simulate() agrees that this point diverges at this step
    with pytest.raises(idm_rs.DivergenceError):
        simulate_point(ds, bad, P, WAVE, t_end=kw["t_end"], dt=kw["dt"], model="lps", save_every=10**6)

    retried = idm_rs.sweep(P, WAVE, grid, retries=2, **kw)
    assert int(retried.status.values[bad]) == 2
    dt_used = float(retried.dt_used.values[bad])
    assert dt_used < kw["dt"]
    assert math.isfinite(float(retried.final_position.values[bad]))
    # the retried point is simulate() at the smaller step, and the good one is untouched
    r = simulate_point(retried, bad, P, WAVE, t_end=kw["t_end"], dt=dt_used, model="lps", save_every=10**6)
    assert float(retried.final_position.values[bad]) == r.final_position
    assert retried.final_position.values[good].tobytes() == ds.final_position.values[good].tobytes()


# --- dopri5 ---------------------------------------------------------------------------------------


def test_dopri5_agrees_with_rk4():
    grid = {"mass_ratio": [0.25, 1.0, 2.0], "voltage": [40.0, 120.0]}
    kw = dict(t_end=2e-3, model="lps", progress=False)
    rk4 = idm_rs.sweep(P, WAVE, grid, dt=2e-8, method="rk4", **kw)
    dp = idm_rs.sweep(P, WAVE, grid, dt=2e-8, method="dopri5", rtol=1e-7, atol=1e-7, **kw)
    assert (rk4.status.values == 1).all() and (dp.status.values == 1).all()
    diff = np.abs(dp.final_position.values - rk4.final_position.values)
    assert diff.max() < 1e-9, diff
    assert (dp.steps.values < rk4.steps.values).all()
    assert dp.attrs["method"] == "dopri5" and dp.attrs["rtol"] == 1e-7 and dp.attrs["atol"] == 1e-7


@pytest.mark.parametrize("method", ["dopri5", "rodas4", "auto"])
def test_adaptive_sweeps_need_no_dt(method):
    """The issue's complaint: ``sweep(..., method="dopri5")`` without ``dt`` was a TypeError."""
    grid = {"mass_ratio": [0.25, 2.0], "voltage": [40.0, 120.0]}
    kw = dict(t_end=2e-3, model="lps", progress=False)
    rk4 = idm_rs.sweep(P, WAVE, grid, dt=1e-8, **kw)
    ds = idm_rs.sweep(P, WAVE, grid, method=method, **kw)
    assert (ds.status.values == 1).all()
    assert np.abs(ds.final_position.values - rk4.final_position.values).max() < 1e-9
    assert (ds.steps.values < rk4.steps.values / 10).all()
    resolved = idm_rs.core.methods.AUTO[0] if method == "auto" else method
    assert ds.attrs["method"] == resolved and ds.attrs["method_asked"] == method
    assert math.isnan(ds.attrs["dt_s"]) and ds.attrs["first_step_s"] == 1e-8


def test_rodas4_sweep_point_equals_rodas4_simulate():
    ds = idm_rs.sweep(P, WAVE, {"voltage": [70.0]}, t_end=2e-3, model="lps", method="rodas4", rtol=1e-6,
                      atol=1e-6, progress=False)
    r = idm_rs.simulate(P, idm_rs.Triangle(70.0, WAVE.rise, WAVE.fall), t_end=2e-3, model="lps", method="rodas4",
                        rtol=1e-6, atol=1e-6, first_step=1e-8)
    assert ds.final_position.values[0] == r.final_position


# --- errors ---------------------------------------------------------------------------------------


@pytest.mark.parametrize(
    "grid, kw, needle",
    [
        ({"nosuch": [1.0]}, {}, "nosuch"),
        ({"mass_ratio": []}, {}, "mass_ratio"),
        ({"mass_ratio": [1.0, float("nan")]}, {}, "mass_ratio"),
        ({}, {}, "empty"),
        ({"voltage": [40.0], "amplitude": [50.0]}, {}, "voltage"),
        ({"mass_ratio": [1.0], "m2": [0.3]}, {}, "mass_ratio"),
        ({"frequency": [100.0]}, {}, "frequency"),
        ({"mass_ratio": [1.0]}, {"method": "euler"}, "method"),
        ({"mass_ratio": [1.0]}, {"model": "fem"}, "model"),
        ({"mass_ratio": [1.0]}, {"metrics": ["nosuch_metric"]}, "nosuch_metric"),
        ({"mass_ratio": [1.0]}, {"dt": 3e-8}, "dt"),
        ({"mass_ratio": [1.0]}, {"t_end": 1e-3 + 1e-8}, "t_end"),
        ({"mass_ratio": [1.0, -1.0]}, {}, "m2"),
        ({"mu_k": [0.5, -0.1]}, {}, "mu_k"),
    ],
)
def test_bad_input_raises_value_error_naming_it(grid, kw, needle):
    args = dict(t_end=1e-3, dt=2e-8, model="lps", progress=False)
    args.update(kw)
    with pytest.raises(ValueError, match=needle):
        idm_rs.sweep(P, SHORT_WAVE, grid, **args)


def test_params_must_be_params():
    with pytest.raises(TypeError, match="Params"):
        idm_rs.sweep({"m1": 0.4}, SHORT_WAVE, {"mass_ratio": [1.0]}, t_end=1e-3, dt=2e-8, progress=False)
