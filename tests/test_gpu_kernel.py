"""The GPU sweep kernel's physics, verified on the CPU: the same source (python/idm_rs/gpu/
idm_kernel.cu) compiled by the system C compiler against the Rust engine on random points, and
the sweep's launch path run through that build. The GPU itself is tested only where CuPy finds
one (skipped otherwise)."""

from __future__ import annotations

import os
import shutil

import numpy as np
import pytest
from hypothesis import HealthCheck, given, note, settings
from hypothesis import strategies as st

import idm_rs
from idm_rs.batch import Point, Structure, param_row, run
from idm_rs.gpu import GpuUnavailable, prepare, run_cpu, run_cuda

# only a missing compiler may skip: a kernel that fails to compile, or whose constants' layout
# disagrees with the engine's, fails the tests below (run_cpu raises)
HAVE_CC = bool(os.environ.get("CC") or shutil.which("cc") or shutil.which("gcc"))
needs_cc = pytest.mark.skipif(not HAVE_CC, reason="no C compiler to build the kernel for the CPU")


@needs_cc
def test_the_kernel_builds_for_the_cpu():
    out = run_cpu(prepare(Structure("lps", 1).config(method="rk4", dt=1e-7), np.array([param_row(idm_rs.Params())]),
                          [idm_rs.Triangle().breakpoints()], 1e-6, 1e-7))
    assert out["status"][0] == 1

P = idm_rs.Params()
W = idm_rs.Triangle(80.0, 0.5e-3, 9.5e-3)


@needs_cc
@settings(max_examples=25, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(
    model=st.sampled_from([("lps", 1), ("dps", 1), ("dps", 3), ("dps", 5)]),
    hysteresis=st.booleans(),
    m2=st.floats(0.1, 0.8),
    mu_k=st.floats(0.3, 0.55),
    sigma1=st.floats(0.0, 200.0),
    volts=st.floats(-120.0, 120.0),
    rise_steps=st.integers(5, 40),
)
def test_kernel_physics_matches_the_engine(model, hysteresis, m2, mu_k, sigma1, volts, rise_steps):
    """The kernel's RK4 against the engine's on random devices and fast edges (slews up to
    2.4e7 V/s). The C library's exp and Rust's may differ in the last ulp, which slip transitions
    amplify to ~1e-8 of a peak velocity (measured 8e-9) and, at such slews, can carry one side
    and not the other through a step that ends just past the presliding bound: there, at half
    the step, both must finish and agree."""
    p = P.replace(m2=m2, mu_k=mu_k, mu_s=max(P.mu_s, mu_k), sigma1=sigma1)
    w = idm_rs.Triangle(volts, rise_steps * 1e-6, 0.4e-3)
    st_ = Structure(model[0], model[1], hysteresis)

    def both(dt: float):
        ref = run([Point(p, waveform=w)], st_, t_end=0.6e-3, method="rk4", dt=dt, retries=0)
        out = run_cpu(prepare(st_.config(method="rk4", dt=dt), np.array([param_row(p)]), [w.breakpoints()], 0.6e-3,
                              dt))
        return ref, out

    ref, out = both(2e-8)
    if out["status"][0] != ref["status"][0]:
        note(f"statuses {ref['status'][0]} (engine) and {out['status'][0]} (kernel) at 2e-8 s: a borderline step")
        ref, out = both(1e-8)
        assert out["status"][0] == ref["status"][0] == 1
    if ref["status"][0] == 1:
        assert abs(out["final_position"][0] - ref["final_position"][0]) <= 1e-12
        for k in ("peak_velocity", "peak_friction"):
            assert out[k][0] == pytest.approx(ref[k][0], rel=1e-7, abs=1e-15), k
        assert out["slip_fraction"][0] == pytest.approx(ref["slip_fraction"][0], abs=1e-9)


@needs_cc
def test_kernel_sweep_equals_the_cpu_sweep_including_a_retried_point():
    g = {"mass_ratio": [0.25, 1.0, 2.0], "voltage": [40.0, 120.0]}
    kw = dict(t_end=2e-3, dt=1e-7, model="lps", progress=False, retries=2)
    a = idm_rs.sweep(P, W, g, **kw)
    b = idm_rs.sweep(P, W, g, backend="kernel-cpu", **kw)
    assert (a.status.values == 2).any(), "expected a point the kernel sees diverge"
    np.testing.assert_array_equal(a.status.values, b.status.values)
    np.testing.assert_allclose(b.final_position.values, a.final_position.values, rtol=0, atol=1e-12)
    np.testing.assert_allclose(b.peak_friction.values, a.peak_friction.values, rtol=1e-9)
    assert b.attrs["backend"] == "kernel-cpu"


@needs_cc
@pytest.mark.parametrize("method", ["dopri5", "auto"])
def test_adaptive_kernel_sweep_equals_the_cpu_sweep(method):
    g = {"mass_ratio": [0.25, 2.0], "voltage": [40.0, 120.0]}
    kw = dict(t_end=10e-3, model="lps", progress=False, method=method)
    a = idm_rs.sweep(P, W, g, **kw)
    b = idm_rs.sweep(P, W, g, backend="kernel-cpu", **kw)
    assert (b.status.values == 1).all() and (b.reason.values == "").all()
    assert a.attrs["rtol"] == b.attrs["rtol"] and a.attrs["method"] == b.attrs["method"]
    # Dormand-Prince on both; "auto" on the CPU may hand a stiff stretch to Rodas4 (1 nm budget)
    tol = 1e-10 if method == "dopri5" else 1e-9
    np.testing.assert_allclose(b.final_position.values, a.final_position.values, rtol=0, atol=tol)
    assert np.isfinite(b.dt_used.values).all() and (b.dt_used.values > 0).all()
    if method == "dopri5":
        np.testing.assert_allclose(b.steps.values.astype(float), a.steps.values.astype(float), rtol=0.05)


@needs_cc
def test_adaptive_kernel_stops_a_crawling_point_and_the_cpu_finishes_it_with_auto():
    """A near-frictionless contact holds Dormand-Prince at its stability limit: the kernel stops
    it at its first crawl check (as the engine does) instead of hanging its thread; rerun on the
    CPU with "auto", it changes to Rodas4 and finishes, equal to rodas4 run directly."""
    slick = P.replace(mu_k=1e-6, mu_s=1e-6)
    w = idm_rs.Triangle(50.0, 0.5e-3, 0.5e-3)
    g = {"voltage": [50.0, 60.0]}
    kw = dict(t_end=1e-3, model="lps", progress=False, backend="kernel-cpu")
    flagged = idm_rs.sweep(slick, w, g, method="auto", retries=0, **kw)
    assert (flagged.status.values == 3).all()
    assert all("step collapsed on the kernel" in r for r in flagged.reason.values)
    assert (flagged.diverged_at.values > 0).all() and (flagged.diverged_at.values < 1e-3).all()
    again = idm_rs.sweep(slick, w, g, method="auto", **kw)
    assert (again.status.values == 1).all(), again.reason.values
    assert all("finished on the CPU engine" in r for r in again.reason.values)
    direct = idm_rs.sweep(slick, w, g, method="auto", t_end=1e-3, model="lps", progress=False)
    np.testing.assert_array_equal(again.final_position.values, direct.final_position.values)


@pytest.mark.parametrize("kw, needle", [
    (dict(method="rodas4"), "rodas4 runs on backend='cpu'"),
    (dict(effects=idm_rs.Effects(k_ground=1e3)), "k_ground"),
])
def test_kernel_backends_refuse_what_they_do_not_run(kw, needle):
    with pytest.raises(ValueError, match=needle):
        idm_rs.sweep(P, W, {"voltage": [80.0]}, t_end=1e-4, model="lps", progress=False, backend="kernel-cpu", **kw)


def test_kernel_constants_refuse_models_the_kernel_cannot_run():
    from idm_rs import engine

    with pytest.raises(ValueError, match="at most 6 nodes"):
        engine.kernel_constants(Structure("dps", 8).config(method="rk4", dt=1e-8), np.array([param_row(P)]))


def test_cuda_backend_without_a_gpu_says_how_to_get_one():
    try:
        import cupy  # noqa: F401

        pytest.skip("CuPy is installed here")
    except ImportError:
        pass
    with pytest.raises(GpuUnavailable, match=r"idm-rs\[cuda\]"):
        idm_rs.sweep(P, W, {"voltage": [80.0]}, t_end=1e-4, dt=1e-8, model="lps", progress=False, backend="cuda")


def _gpu() -> bool:
    try:
        import cupy as cp

        return cp.cuda.runtime.getDeviceCount() > 0
    except Exception:
        return False


@pytest.mark.skipif(not _gpu(), reason="no CUDA device (CuPy)")
def test_gpu_equals_the_cpu_build():
    rows = [param_row(P.replace(m2=m)) for m in np.linspace(0.1, 0.6, 64)]
    b = prepare(Structure("lps", 1).config(method="rk4", dt=5e-8), np.array(rows), [W.breakpoints()] * 64, 2e-3, 5e-8)
    g, c = run_cuda(b), run_cpu(b)
    np.testing.assert_allclose(g["final_position"], c["final_position"], rtol=0, atol=1e-12)


@needs_cc
def test_adaptive_kernel_agrees_with_the_engines_dopri5():
    """The per-thread Dormand-Prince (same tableau, controller and error norm as dopri5.rs):
    not step-for-step identical (breakpoint landing differs in the last bits) but within 1e-10 m
    of the engine's dopri5 and with the same step counts to 5 %."""
    pts, rows, bps = [], [], []
    for m2, v in ((0.2, 120.0), (0.3, 80.0), (0.6, 50.0)):
        p, w = P.replace(m2=m2), idm_rs.Triangle(v, 0.5e-3, 9.5e-3)
        pts.append(Point(p, waveform=w))
        rows.append(param_row(p))
        bps.append(w.breakpoints())
    st_ = Structure("lps", 1, True)
    ref = run(pts, st_, t_end=10e-3, method="dopri5", rtol=1e-6, atol=1e-6, first_step=1e-8)
    out = run_cpu(prepare(st_.config(method="rk4", dt=1e-8), np.array(rows), bps, 10e-3, 1e-8, method="dopri5",
                          rtol=1e-6, atol=1e-6, first_step=1e-8))
    assert (out["status"] == 1).all()
    np.testing.assert_allclose(out["final_position"], ref["final_position"], rtol=0, atol=1e-10)
    np.testing.assert_allclose(out["steps"].astype(float), ref["steps"].astype(float), rtol=0.05)
