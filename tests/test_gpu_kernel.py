"""The GPU sweep kernel, verified without a GPU: NVRTC builds the specialisations the CUDA backend
launches (as CuPy compiles it: the right-hand side the engine generates from its model) with its
state in registers (ptxas: 0 bytes of stack, no spills); the same source compiled by the system
C compiler equals the Rust engine on points drawn over every parameter and every effect; and the
kernel backends refuse, by name, anything else. The GPU itself is tested only where CuPy finds
one (skipped otherwise)."""

from __future__ import annotations

import dataclasses
import os
import shutil
from concurrent.futures import ThreadPoolExecutor

import numpy as np
import pytest
from hypothesis import HealthCheck, given, note, settings
from hypothesis import strategies as st

import idm_rs
from conftest import EFFECT_RANGES, some_effects
from idm_rs.core import engine
from idm_rs.core.batch import Structure, param_row
from idm_rs.gpu import GpuUnavailable, all_specs, kernel_source, prepare, run_cpu, run_cuda
from idm_rs.gpu.backend import ENTRY, NVRTC_OPTIONS

# only a missing compiler may skip: a kernel that fails to compile, or whose constants' layout
# disagrees with the engine's, fails the tests below (run_cpu raises)
HAVE_CC = bool(os.environ.get("CC") or shutil.which("cc") or shutil.which("gcc"))
needs_cc = pytest.mark.skipif(not HAVE_CC, reason="no C compiler to build the kernel for the CPU")

P = idm_rs.Params()
W = idm_rs.Triangle(80.0, 0.5e-3, 9.5e-3)
ACCEPTS = engine.kernel_accepts()


def _triangle_fields(w: idm_rs.Triangle) -> tuple[str, dict[str, float]]:
    return "triangle", w.batch_fields()


@needs_cc
def test_the_kernel_builds_for_the_cpu():
    out = run_cpu(prepare(Structure("lps", 1).config(method="rk4", dt=1e-7), np.array([param_row(P)]),
                          _triangle_fields(idm_rs.Triangle()), 1e-6, 1e-7))
    assert out["status"][0] == 1


# --- NVRTC: the kernel as the CUDA backend compiles it --------------------------------------------


def _nvrtc():
    """NVRTC (the nvidia-cuda-nvrtc wheel; no GPU needed). CI sets IDM_RS_REQUIRE_NVRTC=1, so
    a missing library fails there instead of skipping."""
    from idm_rs.gpu import nvrtc

    try:
        nvrtc._library()
    except nvrtc.NvrtcUnavailable:
        if os.environ.get("IDM_RS_REQUIRE_NVRTC"):
            raise
        pytest.skip("no NVRTC here (pip install nvidia-cuda-nvrtc)")
    return nvrtc


@pytest.mark.parametrize("arch", ["sm_80", "sm_90"])
def test_nvrtc_builds_every_kernel_the_backend_launches_with_no_stack_and_no_spills(arch):
    """Every node count (LPS and DPS 1-5 elements, hysteresis on and off) with no effect, and the
    LPS, the DPS 4 and the DPS 5 with every effect on (the largest generated right-hand sides),
    both entry points, compiled with the CUDA backend's NVRTC options: it compiles, and ptxas
    reports 0 bytes of stack frame and 0 bytes of spills (the state and stages in registers or
    the block's shared memory). The kernel before issue 32 failed here twice: NVRTC had no
    INFINITY, ptxas 840/1,320 bytes; the DPS 4 with every effect spilled 8 bytes for sm_90 until
    its stage output moved to shared memory (Spec.shared_stages)."""
    nvrtc = _nvrtc()
    specs = all_specs()
    assert {s.nodes for s in specs} == set(range(2, ACCEPTS["max_dof"] + 1))
    with ThreadPoolExecutor(max_workers=os.cpu_count() or 2) as pool:
        logs = list(pool.map(lambda s: nvrtc.compile_report(kernel_source(s), arch, NVRTC_OPTIONS), specs))
    for spec, (rc, log) in zip(specs, logs):
        assert rc == 0, f"{spec}: NVRTC failed:\n{log[:3000]}"
        res = {r.name: r for r in nvrtc.resources(log)}
        assert set(ENTRY.values()) <= set(res), f"{spec}: {sorted(res)}"
        for name in ENTRY.values():
            r = res[name]
            print(f"{arch} nodes={spec.nodes} rhs={len(spec.rhs.splitlines())} lines {name}: {r.registers} registers, "
                  f"{r.stack} B stack, {r.spill_stores}/{r.spill_loads} B spills")
            assert r.stack == 0 and r.spill_stores == 0 and r.spill_loads == 0, f"{arch} {spec}: {r}"


def test_nvrtc_report_reads_stack_and_spills():
    """The report parser on ptxas's own words (so a changed format fails here, not silently)."""
    from idm_rs.gpu.nvrtc import resources

    log = ("ptxas info    : Compiling entry function 'idm_rk4_sweep' for 'sm_90'\n"
           "ptxas info    : Function properties for idm_rk4_sweep\n"
           "ptxas         .     840 bytes stack frame, 8 bytes spill stores, 16 bytes spill loads\n"
           "ptxas info    : Used 127 registers, used 0 barriers, 840 bytes cumulative stack size\n")
    (r,) = resources(log)
    assert (r.name, r.registers, r.stack, r.spill_stores, r.spill_loads) == ("idm_rk4_sweep", 127, 840, 8, 16)


# --- the physics: kernel-cpu against the engine, over everything the kernel admits ----------------

#: the drawn parameters: factors on Table 1 (0 defaults: an offset); load_force in N
_SPECIAL = {"load_force": (-0.4, 0.4)}


@st.composite
def kernel_params(draw) -> idm_rs.Params:
    """A device with every parameter the kernel admits (engine.kernel_accepts) drawn: 0.7-1.4
    times Table 1 (the normal force of the device's weight), load_force in +-0.4 N."""
    table = dict(zip(engine.param_names(), param_row(P)))
    kw = {}
    for name in ACCEPTS["params"]:
        if name in _SPECIAL:
            kw[name] = draw(st.floats(*_SPECIAL[name]))
            continue
        base = P.effective_normal_force if name == "normal_force" else table[name]
        kw[name] = base * draw(st.floats(0.7, 1.4))
    kw["mu_s"] = max(kw["mu_s"], kw["mu_k"])
    if draw(st.booleans()):
        kw["normal_force"] = None  # derived from the drawn masses
    return P.replace(**kw)


@st.composite
def kernel_waves(draw, t_end: float):
    """A Triangle or a Sawtooth train (the families the kernel admits) ending within t_end,
    its breakpoints on a 1 us grid (so on every RK4 step grid used here)."""
    amp = draw(st.floats(-120.0, 120.0))
    us = 1e-6
    delay = draw(st.sampled_from([0.0, 20 * us]))
    if draw(st.booleans()):
        rise = draw(st.integers(5, 60)) * us
        fall = draw(st.integers(20, 300)) * us
        return idm_rs.Triangle(amp, rise, fall, delay)
    period = draw(st.sampled_from([100, 125, 200])) * us
    cycles = draw(st.integers(1, int((t_end - delay) / period)))
    rise = draw(st.integers(5, 40)) * us
    return idm_rs.Sawtooth(amp, 1.0 / period, cycles, rise, draw(st.sampled_from(["forward", "backward"])), delay)


MODELS = st.sampled_from([("lps", 1), ("dps", 1), ("dps", 3), ("dps", 5)])
T_END = 0.5e-3


def _sweep(p, w, model, hysteresis, **kw):
    # skip_cycles 0: a drawn train may have one cycle, and the steady state is not compared here
    return idm_rs.sweep(p, w, {"voltage": [w.amplitude]}, t_end=T_END, model=model[0], n_elements=model[1],
                        piezo_hysteresis=hysteresis, progress=False, skip_cycles=0, **kw)


@needs_cc
@settings(max_examples=30, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(p=kernel_params(), w=kernel_waves(T_END), model=MODELS, hysteresis=st.booleans())
def test_kernel_rk4_equals_the_engine_over_every_admitted_parameter(p, w, model, hysteresis):
    """RK4 on the kernel's CPU build equals the engine's to 1e-12 m on devices drawn over every
    parameter the kernel admits, with Triangle and Sawtooth inputs. The C library's exp and
    Rust's may differ in the last ulp, which a step ending just past the presliding bound can
    turn into a divergence on one side only: there, at half the step, both must finish."""
    def both(dt: float):
        kw = dict(method="rk4", dt=dt, retries=0)
        return _sweep(p, w, model, hysteresis, **kw), _sweep(p, w, model, hysteresis, backend="kernel-cpu", **kw)

    ref, out = both(2e-8)
    if out.status.values[0] != ref.status.values[0]:
        note(f"statuses {ref.status.values[0]} (engine) and {out.status.values[0]} (kernel) at 2e-8 s")
        ref, out = both(1e-8)
        assert out.status.values[0] == ref.status.values[0] == 1
    if ref.status.values[0] == 1:
        assert abs(out.final_position.values[0] - ref.final_position.values[0]) <= 1e-12
        for k in ("peak_velocity", "peak_friction"):
            assert out[k].values[0] == pytest.approx(ref[k].values[0], rel=1e-7, abs=1e-15), k
        assert out.slip_fraction.values[0] == pytest.approx(ref.slip_fraction.values[0], abs=1e-9)


@needs_cc
@settings(max_examples=12, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(p=kernel_params(), w=kernel_waves(T_END), model=MODELS, hysteresis=st.booleans(),
       method=st.sampled_from(["dopri5", "auto"]))
def test_kernel_adaptive_is_within_a_nanometre_of_the_engines_rk4(p, w, model, hysteresis, method):
    """The kernel's Dormand-Prince (a crawling point rerun on the CPU, as the sweep does) within
    1 nm of the engine's RK4 at dt = 1e-8 s on the same drawn devices and inputs."""
    ref = _sweep(p, w, model, hysteresis, method="rk4", dt=1e-8)
    out = _sweep(p, w, model, hysteresis, method=method, backend="kernel-cpu")
    # a stiff drawn contact (presliding stiffness 1.5e10 with mu_k 0.625 and fric_n 1.25) takes
    # RK4 past its stability at 1e-8 s: the sweep's retry at 5e-9 s is the reference then
    assert ref.status.values[0] in (1, 2), ref.reason.values
    assert out.status.values[0] == 1, out.reason.values
    assert abs(out.final_position.values[0] - ref.final_position.values[0]) <= 1e-9


#: each library coefficient at a size giving ~0.05 N at the states of these runs (x ~ 1 um,
#: v ~ 10 mm/s, V ~ 100 V, dV/dt ~ 1e5 V/s, t ~ 1 ms, Ff ~ 1 N)
LIBRARY_SIZES = {
    "lib_x1": 5e4, "lib_v1": 5.0, "lib_dx": 5e4, "lib_dv": 5.0, "lib_sgn": 0.05, "lib_abs": 5.0, "lib_vv": 500.0,
    "lib_volt": 5e-4, "lib_dvolt": 5e-7, "lib_t": 50.0, "lib_x1sq": 5e10, "lib_x1cube": 5e16, "lib_sin": 0.05,
    "lib_cos": 0.05, "lib_ff": 0.05, "lib_ff_sin": 0.05, "lib_ff_cos": 0.05, "libw_x2": 5e4, "libw_v2": 5.0,
    "libw_dx": 5e4, "libw_dv": 5.0, "libw_sgn": 0.05, "libw_vv": 500.0, "libw_volt": 5e-4, "libw_dvolt": 5e-7,
}
#: every catalogue effect on its own (creep as its pair), then every library term
EVERY_EFFECT = ([{name: EFFECT_RANGES[name][1]} for name in sorted(EFFECT_RANGES)]
                + [{"kappa": 0.03, "tau_creep": 1e-3}]
                + [{name: size, "lib_wavelength": 3e-6} for name, size in LIBRARY_SIZES.items()])


@st.composite
def kernel_effects(draw) -> idm_rs.Effects:
    """Up to three catalogue effects (conftest.some_effects) and up to three library terms at
    0.2-1 times their LIBRARY_SIZES, either sign."""
    e = draw(some_effects())
    terms = draw(st.lists(st.sampled_from(sorted(LIBRARY_SIZES)), max_size=3, unique=True))
    lib = {t: LIBRARY_SIZES[t] * draw(st.floats(0.2, 1.0)) * draw(st.sampled_from([-1.0, 1.0])) for t in terms}
    if terms:
        lib["lib_wavelength"] = draw(st.floats(1e-6, 1e-5))
    return dataclasses.replace(e, **lib)


def test_every_effect_and_library_term_is_admitted_and_exercised_here():
    """The lists above cover what the engine declares: a new effect parameter fails here until
    the kernel tests draw it."""
    assert set().union(*EVERY_EFFECT) == set(engine.effect_names())
    assert set(ACCEPTS["effects"]) == set(engine.effect_names())


@needs_cc
@pytest.mark.parametrize("effect", EVERY_EFFECT, ids=lambda e: "+".join(sorted(e)))
@pytest.mark.parametrize("model", [("lps", 1), ("dps", 3)])
def test_kernel_rk4_equals_the_engine_with_each_effect(effect, model):
    """Every catalogue effect and every library term, alone, on the LPS and a DPS with
    hysteresis: the generated right-hand side on the kernel's CPU build equals the engine to
    1e-12 m (RK4), and its adaptive run is within 1 nm of the engine's RK4 at 1e-8 s."""
    e = idm_rs.Effects(**effect)
    w = idm_rs.Sawtooth(100.0, 5000.0, 2, 40e-6)
    ref = _sweep(P, w, model, True, method="rk4", dt=1e-8, retries=0, effects=e)
    out = _sweep(P, w, model, True, method="rk4", dt=1e-8, retries=0, effects=e, backend="kernel-cpu")
    assert ref.status.values[0] == out.status.values[0] == 1, (ref.reason.values, out.reason.values)
    assert abs(out.final_position.values[0] - ref.final_position.values[0]) <= 1e-12
    assert out.peak_friction.values[0] == pytest.approx(ref.peak_friction.values[0], rel=1e-7)
    if not set(effect) & {"drift_rate", "tau_sensor"}:  # those change what the sensor reads, not x1
        plain = _sweep(P, w, model, True, method="rk4", dt=1e-8, retries=0)
        assert abs(plain.final_position.values[0] - ref.final_position.values[0]) > 1e-11, "the effect changes nothing"
    ad = _sweep(P, w, model, True, method="dopri5", effects=e, backend="kernel-cpu")
    assert ad.status.values[0] == 1, ad.reason.values
    assert abs(ad.final_position.values[0] - ref.final_position.values[0]) <= 1e-9


@needs_cc
@settings(max_examples=20, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(p=kernel_params(), w=kernel_waves(T_END), model=MODELS, hysteresis=st.booleans(), e=kernel_effects())
def test_kernel_equals_the_engine_over_drawn_effects(p, w, model, hysteresis, e):
    """Drawn devices with up to three catalogue effects and three library terms at once: RK4 on
    the kernel's CPU build equals the engine's to 1e-12 m (both at half the step where one
    side alone diverged, as above); its Dormand-Prince within 1 nm of the engine's RK4."""
    def both(dt: float):
        kw = dict(method="rk4", dt=dt, retries=0, effects=e)
        return _sweep(p, w, model, hysteresis, **kw), _sweep(p, w, model, hysteresis, backend="kernel-cpu", **kw)

    ref, out = both(1e-8)
    if out.status.values[0] != ref.status.values[0]:
        note(f"statuses {ref.status.values[0]} (engine) and {out.status.values[0]} (kernel) at 1e-8 s")
        ref, out = both(5e-9)
        assert out.status.values[0] == ref.status.values[0]
    if ref.status.values[0] != 1:
        return
    assert abs(out.final_position.values[0] - ref.final_position.values[0]) <= 1e-12
    ad = _sweep(p, w, model, hysteresis, method="dopri5", effects=e, backend="kernel-cpu")
    assert ad.status.values[0] == 1, ad.reason.values
    assert abs(ad.final_position.values[0] - ref.final_position.values[0]) <= 1e-9


@needs_cc
def test_load_force_moves_the_kernel_as_it_moves_the_engine():
    """The designer's load curve: a load on the main body changes x1 (1.678 / 2.320 / 2.841 um
    for 0, 0.5, 1 N on the paper's LPS); the kernel no longer drops it."""
    g = {"load_force": [0.0, 0.5, 1.0]}
    kw = dict(t_end=10e-3, dt=5e-8, model="lps", progress=False, method="rk4")
    a = idm_rs.sweep(P, W, g, **kw)
    b = idm_rs.sweep(P, W, g, backend="kernel-cpu", **kw)
    np.testing.assert_allclose(b.final_position.values, a.final_position.values, rtol=0, atol=1e-12)
    np.testing.assert_allclose(a.final_position.values, [1.678e-6, 2.320e-6, 2.841e-6], rtol=0, atol=1e-9)


@needs_cc
def test_kernel_sweep_equals_the_cpu_sweep_including_a_retried_point():
    g = {"mass_ratio": [0.25, 1.0, 2.0], "voltage": [40.0, 120.0]}
    kw = dict(t_end=2e-3, dt=1e-7, model="lps", progress=False, retries=2)
    a = idm_rs.sweep(P, W, g, **kw)
    b = idm_rs.sweep(P, W, g, backend="kernel-cpu", block_size=4, **kw)
    assert (a.status.values == 2).any(), "expected a point the kernel sees diverge"
    np.testing.assert_array_equal(a.status.values, b.status.values)
    np.testing.assert_allclose(b.final_position.values, a.final_position.values, rtol=0, atol=1e-12)
    np.testing.assert_allclose(b.peak_friction.values, a.peak_friction.values, rtol=1e-9)
    assert b.attrs["backend"] == "kernel-cpu"


@needs_cc
def test_kernel_sawtooth_sweep_flags_an_edge_longer_than_the_period_as_the_cpu_does():
    """A swept sawtooth: frequency and edge per point from the wave's few numbers; where the
    edge is not shorter than the period (valid on each axis alone) the point is invalid,
    status 4, as on the CPU."""
    saw = idm_rs.Sawtooth(80.0, 500.0, 2, 0.1e-3)
    g = {"frequency": [500.0, 2500.0], "rise": [0.1e-3, 0.5e-3]}
    kw = dict(t_end=4e-3, dt=5e-8, model="dps", n_elements=2, progress=False, metrics=["final_position"])
    a = idm_rs.sweep(P, saw, g, **kw)
    b = idm_rs.sweep(P, saw, g, backend="kernel-cpu", **kw)
    np.testing.assert_array_equal(b.status.values, a.status.values)
    np.testing.assert_array_equal(b.status.values, [[1, 1], [1, 4]])
    ok = b.status.values == 1
    np.testing.assert_allclose(b.final_position.values[ok], a.final_position.values[ok], rtol=0, atol=1e-12)
    assert "rise" in b.reason.values[1, 1]


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


@needs_cc
def test_adaptive_kernel_agrees_with_the_engines_dopri5():
    """The per-thread Dormand-Prince (same tableau, controller and error norm as integrate/dopri5.rs):
    not step-for-step identical (breakpoint landing differs in the last bits) but within 1e-10 m
    of the engine's dopri5 and with the same step counts to 5 %."""
    g = {"mass_ratio": [0.5, 0.75, 1.5], "voltage": [50.0, 80.0, 120.0]}
    kw = dict(t_end=10e-3, model="lps", progress=False, method="dopri5", rtol=1e-6, atol=1e-6, first_step=1e-8)
    ref = idm_rs.sweep(P, W, g, **kw)
    out = idm_rs.sweep(P, W, g, backend="kernel-cpu", retries=0, **kw)
    assert (out.status.values == 1).all()
    np.testing.assert_allclose(out.final_position.values, ref.final_position.values, rtol=0, atol=1e-10)
    np.testing.assert_allclose(out.steps.values.astype(float), ref.steps.values.astype(float), rtol=0.05)


# --- refuse by default ----------------------------------------------------------------------------


@pytest.mark.parametrize("kw, needle", [
    (dict(method="rodas4"), "rodas4 runs on backend='cpu'"),
    (dict(model="dps", n_elements=6), r"up to 6 nodes \(5 elements\)"),
    (dict(metrics=["final_position", "mean_velocity"]), r"steady-state metric\(s\) \['mean_velocity'\]"),
])
def test_kernel_backends_refuse_what_they_do_not_run(kw, needle):
    base = dict(t_end=1e-4, model="lps", progress=False, backend="kernel-cpu")
    with pytest.raises(ValueError, match=needle) as e:
        idm_rs.sweep(P, W, {"voltage": [80.0]}, **{**base, **kw})
    assert "backend='cpu'" in str(e.value)


def test_kernel_backends_refuse_a_sampled_input_by_name():
    kw = dict(t_end=1e-4, model="lps", progress=False, backend="kernel-cpu")
    s = idm_rs.Sampled([0.0, 1e-4], [0.0, 80.0])
    with pytest.raises(ValueError, match="not a Sampled waveform.*use backend='cpu'"):
        idm_rs.sweep(P, s, {"amplitude": [1.0]}, **kw)


def test_a_parameter_the_kernel_does_not_declare_is_refused(monkeypatch):
    """Admission is by the engine's list: a Table 1 parameter missing from it (as a new field
    would be) is refused as soon as it is swept or set, by name; at its default it passes."""
    reduced = dict(ACCEPTS, params=[n for n in ACCEPTS["params"] if n != "sigma2"])
    monkeypatch.setattr(engine, "kernel_accepts", lambda: reduced)
    kw = dict(t_end=1e-4, dt=1e-8, model="lps", progress=False, backend="kernel-cpu")
    with pytest.raises(ValueError, match=r"parameter 'sigma2' \(swept\).*use backend='cpu'"):
        idm_rs.sweep(P, W, {"sigma2": [0.4, 0.8]}, **kw)
    with pytest.raises(ValueError, match=r"parameter 'sigma2' \(set\)"):
        idm_rs.sweep(P.replace(sigma2=0.8), W, {"voltage": [80.0]}, **kw)
    if HAVE_CC:
        assert idm_rs.sweep(P, W, {"voltage": [80.0]}, **kw).status.values[0] == 1


def test_every_table1_parameter_is_admitted_or_refused_by_the_engines_list():
    assert set(ACCEPTS["params"]) <= set(engine.param_names())
    assert "load_force" in ACCEPTS["params"]
    assert ACCEPTS["effects"] == list(engine.effect_names()) and set(ACCEPTS["waves"]) == {"triangle", "sawtooth"}
    for kind, fields in ACCEPTS["waves"].items():
        assert list(fields) == list(engine.wave_fields(kind))


def test_kernel_program_refuses_models_the_kernel_cannot_run():
    no_effect = np.zeros((1, len(engine.effect_names())))
    with pytest.raises(ValueError, match="at most 6 nodes"):
        engine.kernel_program(Structure("dps", 8).config(method="rk4", dt=1e-8), np.array([param_row(P)]), no_effect)


@needs_cc
def test_a_sweep_that_switches_a_lag_on_at_some_points_is_refused_by_name():
    """A lag adds a state: points with tau_amp = 0 and > 0 have different kernels, so a block that
    mixes them is refused with the fix (the CPU backend groups them by shape)."""
    with pytest.raises(ValueError, match="point 1: .*state differs.*split the sweep"):
        idm_rs.sweep(P, W, {"tau_amp": [0.0, 2e-5]}, t_end=1e-4, dt=1e-8, model="lps", progress=False,
                     backend="kernel-cpu")


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
@pytest.mark.parametrize("nodes", [2, 5])
def test_gpu_equals_the_cpu_build(nodes):
    rows = np.array([param_row(P.replace(m2=m)) for m in np.linspace(0.1, 0.6, 64)])
    st_ = Structure("lps", 1) if nodes == 2 else Structure("dps", nodes - 1)
    for method in ("rk4", "dopri5"):
        waves = ("triangle", dict(amplitude=np.linspace(40, 120, 64), rise=0.5e-3, fall=1.5e-3, delay=0.0))
        b = prepare(st_.config(method="rk4", dt=5e-8), rows, waves, 2e-3, 5e-8, method=method)
        g, c = run_cuda(b), run_cpu(b)
        np.testing.assert_allclose(g["final_position"], c["final_position"], rtol=0, atol=1e-12 if method == "rk4"
                                   else 1e-10)


@pytest.mark.skipif(not _gpu(), reason="no CUDA device (CuPy)")
@pytest.mark.parametrize("model", [("lps", 1), ("dps", 3)])
def test_gpu_equals_the_cpu_build_with_each_effect(model):
    """Every catalogue effect and every library term, alone, on the card: the generated
    right-hand side as the GPU runs it equals its CPU build (RK4 to 1e-12 m; Dormand-Prince within
    1 nm, the GPU's sinpi/cospi against the CPU's sin/cos moving an accepted step at most), over
    16 points of mass and voltage. Up to 80 V, where RK4 at 5e-8 s is converged with every term
    (halving the step moves x1 <= 1.3e-12 m): beyond it the cubic spring runs away (x1 moves
    by 9 um when the step halves) and the card's fused multiply-adds are amplified as the
    step's own error is."""
    names = engine.effect_names()
    st_ = Structure(model[0], model[1], True)
    rows = np.array([param_row(P.replace(m2=m)) for m in np.linspace(0.1, 0.6, 16)])
    waves = ("triangle", dict(amplitude=np.linspace(40, 80, 16), rise=0.5e-3, fall=1.5e-3, delay=0.0))
    wrong = []
    for effect in EVERY_EFFECT:
        table = np.tile([float(effect.get(name, 0.0)) for name in names], (16, 1))
        for method, atol in (("rk4", 1e-12), ("dopri5", 1e-9)):
            b = prepare(st_.config(method="rk4", dt=5e-8), rows, waves, 2e-3, 5e-8, method=method,
                        effects_table=table)
            g, c = run_cuda(b), run_cpu(b)
            gap = float(np.abs(g["final_position"] - c["final_position"]).max())
            if not (g["status"] == c["status"]).all() or not gap <= atol:
                wrong.append(f"{effect} {method}: statuses {g['status']} / {c['status']}, |dx1| {gap:.3g} m")
    assert not wrong, "\n".join(wrong)


@needs_cc
def test_ctrl_c_keeps_the_finished_kernel_blocks(monkeypatch):
    """Ctrl-C during the third block: the two finished blocks are kept, the rest NaN, and the
    Dataset says it is incomplete."""
    import idm_rs.gpu as gpu

    real, calls = gpu.run_cpu, []

    def interrupted(batch):
        calls.append(batch.points)
        if len(calls) == 3:
            raise KeyboardInterrupt
        return real(batch)

    monkeypatch.setattr(gpu, "run_cpu", interrupted)
    g = {"voltage": np.linspace(40.0, 120.0, 10)}
    with pytest.raises(KeyboardInterrupt, match="of 10 points finished") as stop:
        idm_rs.sweep(P, W, g, t_end=1e-4, dt=1e-7, model="lps", progress=False, backend="kernel-cpu",
                     block_size=4)
    ds = idm_rs.partial_result(stop.value)
    assert ds.attrs["complete"] == 0
    assert (ds.status.values[:4] == 1).all() and np.isfinite(ds.final_position.values[:4]).all()
    assert (ds.status.values[8:] == 0).all() and np.isnan(ds.final_position.values[8:]).all()


@needs_cc
def test_a_swept_effect_runs_on_the_kernel_as_on_the_cpu():
    """An effect is a sweep axis like a parameter: k_ground over 0 and two stiffnesses, and the
    amplifier lag over two time constants (its state on at every point), equal to the CPU sweep."""
    kw = dict(t_end=2e-3, dt=1e-8, model="lps", progress=False, method="rk4", retries=0)
    for grid, e in (({"k_ground": [0.0, 2e3, 2e4], "voltage": [60.0, 120.0]}, None),
                    ({"tau_amp": [5e-6, 2e-5]}, idm_rs.Effects(tau_amp=1e-5))):
        a = idm_rs.sweep(P, W, grid, effects=e, **kw)
        b = idm_rs.sweep(P, W, grid, effects=e, backend="kernel-cpu", **kw)
        assert (a.status.values == 1).all() and (b.status.values == 1).all()
        np.testing.assert_allclose(b.final_position.values, a.final_position.values, rtol=0, atol=1e-12)
        assert np.ptp(a.final_position.values) > 1e-9, "the swept effect changes nothing"
