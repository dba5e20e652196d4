"""The vector lanes (rust/src/lanes/mod.rs, lanes/rk4.rs): RK4 batches of plain models run several
points at once, stored component by component and computed as AVX2 / AVX-512 / scalar code
chosen at run time. Whatever the instruction set, every point is bitwise the scalar model's run
(``simulate(energy=True)`` takes the scalar path: its accounting states make the model
non-plain); lanes are refilled from the queue when points of different lengths finish or
diverge. Spans of 0.3-1 ms: the file runs in seconds."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

import idm_rs
from idm_rs.core import engine
from idm_rs.core.batch import Point, Structure, run

LEVELS = ("scalar", "avx2", "avx512")


@pytest.fixture(autouse=True)
def default_level():
    yield
    engine.set_simd_level("avx2")


def _scalar_model(pt: Point, structure: Structure, t_end: float, dt: float) -> np.ndarray:
    """The final state of ``pt`` through the scalar model's right-hand side."""
    r = idm_rs.simulate(pt.params, pt.waveform, t_end=pt.t_end or t_end, dt=dt, model=structure.model,
                        n_elements=structure.n_elements, piezo_hysteresis=structure.piezo_hysteresis,
                        effects=pt.effects, energy=True)
    return np.asarray(r.final_state)


device = st.fixed_dictionaries({
    "m2": st.floats(0.1, 0.8),
    "mu_k": st.floats(0.2, 0.6),
    "sigma1": st.floats(50.0, 200.0),
    "fric_alpha": st.floats(5e9, 4e10),
    "peak": st.sampled_from([True, False]),
    "k_ground": st.sampled_from([0.0, 2e3]),
    "eps": st.sampled_from([0.0, 0.03]),
    "c_weight": st.sampled_from([0.0, 0.2]),
    # any Stribeck exponent and Bouc-Wen exponent: a power per lane (the physics' own code)
    "stribeck_exponent": st.sampled_from([2.0, 1.5, 2.7]),
    "fric_n": st.sampled_from([1.0, 1.4]),
    # library forces (a term of each kind: polynomial, periodic in x1, time, the weight's)
    "library": st.sampled_from([{}, {"lib_x1sq": 2e6, "lib_sin": 0.04, "lib_wavelength": 15e-6, "lib_t": 0.3,
                                     "libw_sgn": 0.01, "lib_ff_cos": 0.02}]),
    "volts": st.floats(20.0, 120.0),
})


@settings(max_examples=12, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(devices=st.lists(device, min_size=1, max_size=11), model=st.sampled_from(["lps", "dps"]),
       n_elements=st.integers(1, 4), hysteresis=st.booleans(), sawtooth=st.booleans())
def test_every_instruction_set_gives_the_scalar_models_bits(devices, model, n_elements, hysteresis, sawtooth):
    structure = Structure(model, n_elements if model == "dps" else 1, hysteresis)
    points = []
    for d in devices:
        p = idm_rs.Params().replace(m2=d["m2"], mu_k=d["mu_k"], sigma1=d["sigma1"], fric_alpha=d["fric_alpha"],
                                    stribeck_exponent=d["stribeck_exponent"], fric_n=d["fric_n"])
        p = p.replace(mu_s=p.mu_k if not d["peak"] else max(p.mu_s, 1.2 * p.mu_k))
        eff = idm_rs.Effects(k_ground=d["k_ground"], eps=d["eps"], c_weight=d["c_weight"], **d["library"])
        wave = (idm_rs.Sawtooth(d["volts"], 2000.0, cycles=1, rise=0.1e-3) if sawtooth
                else idm_rs.Triangle(d["volts"], 0.2e-3, 0.3e-3))
        points.append(Point(p, effects=eff, waveform=wave))
    t_end, dt = 0.5e-3, 2e-8
    outs = {}
    for level in LEVELS:
        engine.set_simd_level(level)
        outs[level] = run(points, structure, t_end=t_end, dt=dt, final_states=True)
    for level in LEVELS[1:]:
        np.testing.assert_array_equal(outs[level]["final_states"], outs["scalar"]["final_states"], err_msg=level)
    for i, pt in enumerate(points):
        if outs["avx2"]["status"][i] != 1:
            continue  # a random device whose friction is too stiff for this step
        mine = outs["avx2"]["final_states"][i]
        # the scalar run's state has the accounting components after the physical ones
        np.testing.assert_array_equal(mine, _scalar_model(pt, structure, t_end, dt)[: mine.size])


def test_the_level_is_reported_and_a_bad_name_refused():
    engine.set_simd_level("scalar")
    assert engine.simd_level() == "scalar"
    engine.set_simd_level("avx2")
    assert engine.simd_level() in ("avx2", "scalar")  # scalar on a processor without AVX2
    with pytest.raises(ValueError, match="simd level must be"):
        engine.set_simd_level("sse9")


def test_lanes_refill_under_mixed_durations_and_divergence():
    """Twelve points of three lengths, two of them with a step too large for their stiff
    friction (they diverge, are retried at dt/2 and dt/4 and finish): every point's result is
    the one it has alone, whatever its neighbours did."""
    wave = idm_rs.Triangle(80.0, 0.2e-3, 0.3e-3)
    base = idm_rs.Params()
    points = []
    for k in range(12):
        p = base.replace(m2=0.2 + 0.02 * k)
        if k in (3, 8):
            p = p.replace(fric_alpha=5e10)  # diverges at dt = 1e-7 and 5e-8, finishes at 2.5e-8
        points.append(Point(p, waveform=wave, t_end=(0.3e-3, 0.6e-3, 1.0e-3)[k % 3]))
    lps = Structure("lps", 1, False)
    out = run(points, lps, t_end=1.0e-3, dt=1e-7, retries=2, final_states=True)
    # 1: finished, 2: finished after retries at a smaller step
    assert [int(s) for s in out["status"]] == [2 if k in (3, 8) else 1 for k in range(12)]
    assert list(out["dt_used"][[3, 8]]) == [2.5e-8, 2.5e-8] and out["dt_used"][0] == 1e-7
    for i, pt in enumerate(points):
        alone = run([pt], lps, t_end=1.0e-3, dt=1e-7, retries=2, final_states=True)
        np.testing.assert_array_equal(out["final_states"][i], alone["final_states"][0])
        assert out["steps"][i] == alone["steps"][0]
    durations = out["steps"] * out["dt_used"]
    assert sorted({round(d * 1e4) for d in durations}) == [3, 6, 10]
