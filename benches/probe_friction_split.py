"""Probe: can the fit step (2e-7 s) keep usable derivatives through fast slips if the presliding
force Fh is split off and sub-cycled at its own stable step?

    python benches/probe_friction_split.py [--trajectory]

At the fit step RK4 over the whole state is beyond the stability limit of Fh in every fast slip
(stiffness |v1| (a/S + b + |c|), ~1e8 1/s at 10 mm/s): the diagnosis then takes forward
differences for its Jacobians (n + 1 runs each; benches/RESULTS.md §47). This script integrates
the LPS of the paper's Table 1 (piezo hysteresis on, a triangle drive) in plain Python, by
Strang splitting: Fh alone over dt/2 at the frozen main-body velocity (RK4 sub-steps at Fh's
stable step), the mechanics by one RK4 step with Fh frozen, Fh again over dt/2. It prints x1 at
10 ms and dx1/dmu_k by forward differences of three sizes (a derivative of a smooth discrete map
agrees across them), against the engine's RK4 at 1e-8 s and at the fit step. A probe, not a
method of the package: second order, Python speed.

With ``--trajectory`` it asks what a larger step would cost in accuracy: x1 read every 10 us
(the recordings' sample step) by the split at 2e-7 ... 2e-6 s, by a coupled step (below) and by
the engine's RK4 at the fit step, each against the engine's RK4 at 1e-8 s, as the largest
difference in nm (the recordings' noise is 1-2 nm). The split freezes v1 over each half step,
which a fast slip does not allow; the coupled step is a predictor-corrector: the mechanics' RK4
step with Fh held at its start value predicts v1 at the step's end, Fh is sub-stepped over the
step along v1 linear between the two (at its own stable step), and the mechanics' step is taken
again with Fh at its start, its middle and its end for RK4's stages.
"""

from __future__ import annotations

import math
from typing import Optional

import numpy as np

import idm_rs


def table1() -> dict[str, float]:
    """The package's defaults (the paper's Table 1) under this script's short names [SI]."""
    q = idm_rs.Params()
    return dict(m1=q.m1, m2=q.m2, kp=q.kp, bc=q.rayleigh_beta, d33=q.d33, a=q.fric_alpha, b=q.fric_beta,
                c=q.fric_gamma, s1=q.sigma1, s2=q.sigma2, mu_k=q.mu_k, mu_s=q.mu_s, vs=q.stribeck_velocity,
                fn=q.effective_normal_force, ha=q.hyst_alpha, hb=q.hyst_beta, hc=q.hyst_gamma)


P = table1()
T_END = 10e-3


def volt(t: float, amp: float, rise: float) -> tuple[float, float]:
    """The triangle's voltage [V] and its rate [V/s]: 0 -> amp over `rise`, back to 0 at T_END."""
    if t < rise:
        return amp * t / rise, amp / rise
    return max(0.0, amp * (1 - (t - rise) / (T_END - rise))), -amp / (T_END - rise)


def stribeck(v: float, p: dict[str, float]) -> float:
    return p["mu_k"] * p["fn"] + (p["mu_s"] - p["mu_k"]) * p["fn"] * math.exp(-min((v / p["vs"]) ** 2, 700.0))


def fh_rate(fh: float, v: float, s: float, p: dict[str, float]) -> float:
    gd = v - abs(v) * fh / s
    return p["a"] * gd - p["b"] * abs(gd) * fh - p["c"] * gd * abs(fh)


def mechanics(t: float, y: np.ndarray, p: dict[str, float], amp: float, rise: float) -> np.ndarray:
    """d/dt of (x1, v1, x2, v2, h) with Fh = y[4] held."""
    x1, v1, x2, v2, fh, h = (float(u) for u in y)
    volts, dv = volt(t, amp, rise)
    gd = v1 - abs(v1) * fh / stribeck(v1, p)
    ff = fh + p["s1"] * gd + p["s2"] * v1
    fp = p["kp"] * (p["d33"] * volts - h - (x1 - x2)) - p["bc"] * p["kp"] * (v1 - v2)
    hd = p["ha"] * p["d33"] * dv - p["hb"] * abs(dv) * h - p["hc"] * dv * abs(h)
    return np.array([v1, (fp - ff) / p["m1"], v2, -fp / p["m2"], 0.0, hd])


def fh_advance(fh: float, v: float, p: dict[str, float], span: float) -> tuple[float, int]:
    """Fh over `span` [s] at frozen v: RK4 sub-steps within RK4's limit (lambda h <= 2)."""
    s = stribeck(v, p)
    m = max(1, math.ceil(abs(v) * (p["a"] / s + p["b"] + abs(p["c"])) * span / 2.0))
    h = span / m
    for _ in range(m):
        k1 = fh_rate(fh, v, s, p)
        k2 = fh_rate(fh + h / 2 * k1, v, s, p)
        k3 = fh_rate(fh + h / 2 * k2, v, s, p)
        k4 = fh_rate(fh + h * k3, v, s, p)
        fh += h / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
    return fh, m


SAMPLE_STEP = 1e-5


def split_run(p: dict[str, float], dt: float, amp: float, rise: float,
              samples: Optional[list[float]] = None) -> tuple[float, float]:
    """(x1 at T_END [m], mean Fh sub-steps per half step); x1 every SAMPLE_STEP into `samples`."""
    y = np.zeros(6)
    n, subs = int(round(T_END / dt)), 0
    every = int(round(SAMPLE_STEP / dt))
    for i in range(n):
        if samples is not None and i % every == 0:
            samples.append(float(y[0]))
        t = i * dt
        y[4], m1 = fh_advance(y[4], y[1], p, dt / 2)
        k1 = mechanics(t, y, p, amp, rise)
        k2 = mechanics(t + dt / 2, y + dt / 2 * k1, p, amp, rise)
        k3 = mechanics(t + dt / 2, y + dt / 2 * k2, p, amp, rise)
        k4 = mechanics(t + dt, y + dt * k3, p, amp, rise)
        y = y + dt / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
        y[4], m2 = fh_advance(y[4], y[1], p, dt / 2)
        subs += m1 + m2
    if samples is not None:
        samples.append(float(y[0]))
    return float(y[0]), subs / (2 * n)


def fh_along(fh: float, v0: float, v1: float, span: float, p: dict[str, float]) -> tuple[float, float, int]:
    """Fh over `span` [s] with v linear from `v0` to `v1`: (Fh at the middle, at the end, sub-steps);
    RK4 sub-steps within its limit (lambda h <= 2), an even number so the middle is a sub-step's end."""
    stiff = max(abs(v0), abs(v1)) * (p["a"] / min(stribeck(v0, p), stribeck(v1, p)) + p["b"] + abs(p["c"]))
    m = 2 * max(1, math.ceil(stiff * span / 4.0))
    h = span / m

    def rate(f: float, tau: float) -> float:
        v = v0 + (v1 - v0) * tau / span
        return fh_rate(f, v, stribeck(v, p), p)

    middle = fh
    for k in range(m):
        t = k * h
        k1 = rate(fh, t)
        k2 = rate(fh + h / 2 * k1, t + h / 2)
        k3 = rate(fh + h / 2 * k2, t + h / 2)
        k4 = rate(fh + h * k3, t + h)
        fh += h / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
        if k + 1 == m // 2:
            middle = fh
    return middle, fh, m


def mechanics_step(t: float, y: np.ndarray, dt: float, fh: tuple[float, float, float], p: dict[str, float],
                   amp: float, rise: float) -> np.ndarray:
    """One RK4 step of the mechanics with Fh given at the step's start, middle and end."""
    def f(tt: float, yy: np.ndarray, force: float) -> np.ndarray:
        z = yy.copy()
        z[4] = force
        return mechanics(tt, z, p, amp, rise)

    k1 = f(t, y, fh[0])
    k2 = f(t + dt / 2, y + dt / 2 * k1, fh[1])
    k3 = f(t + dt / 2, y + dt / 2 * k2, fh[1])
    k4 = f(t + dt, y + dt * k3, fh[2])
    return y + dt / 6 * (k1 + 2 * k2 + 2 * k3 + k4)


def coupled_run(p: dict[str, float], dt: float, amp: float, rise: float, samples: list[float]) -> tuple[float, float]:
    """(x1 at T_END [m], mean Fh sub-steps per step) by the coupled step; x1 every SAMPLE_STEP."""
    y = np.zeros(6)
    n, subs = int(round(T_END / dt)), 0
    every = int(round(SAMPLE_STEP / dt))
    for i in range(n):
        if i % every == 0:
            samples.append(float(y[0]))
        t, fh0 = i * dt, float(y[4])
        predicted = mechanics_step(t, y, dt, (fh0, fh0, fh0), p, amp, rise)
        middle, end, m = fh_along(fh0, float(y[1]), float(predicted[1]), dt, p)
        y = mechanics_step(t, y, dt, (fh0, middle, end), p, amp, rise)
        y[4] = end
        subs += m
    samples.append(float(y[0]))
    return float(y[0]), subs / n


def engine_samples(dt: float, amp: float, rise: float) -> np.ndarray:
    """The engine's x1 [m] every SAMPLE_STEP over [0, T_END] at RK4 step `dt`."""
    w = idm_rs.Triangle(amplitude=amp, rise=rise, fall=T_END - rise, delay=0.0)
    r = idm_rs.simulate(idm_rs.Params(), w, t_end=T_END, dt=dt, model="lps", save_every=int(round(SAMPLE_STEP / dt)))
    return np.asarray(r.main_body)


def trajectory() -> None:
    print("| drive | integrator | step [s] | max |x1 - reference| [nm] | x1 at 10 ms [um] "
          "| Fh sub-steps per half step |")
    print("|---|---|---|---|---|---|")
    for amp, rise in ((80.0, 0.5e-3), (150.0, 0.1e-3)):
        ref = engine_samples(1e-8, amp, rise)
        drive = f"{amp:.0f} V, {rise * 1e3:.1f} ms rise"
        try:
            fit = engine_samples(2e-7, amp, rise)
            print(f"| {drive} | engine RK4 | 2e-7 | {np.max(np.abs(fit - ref)) * 1e9:.3f} | {fit[-1] * 1e6:.5f} | - |")
        except idm_rs.DivergenceError:
            print(f"| {drive} | engine RK4 | 2e-7 | diverges | - | - |")
        for dt in (2e-7, 5e-7, 1e-6, 2e-6):
            xs: list[float] = []
            x, subs = split_run(P, dt, amp, rise, xs)
            err = np.max(np.abs(np.array(xs) - ref)) if len(xs) == ref.size else math.nan
            print(f"| {drive} | split | {dt:.0e} | {err * 1e9:.3f} | {x * 1e6:.5f} | {subs:.1f} |", flush=True)
        for dt in (5e-7, 1e-6, 2e-6):
            xs = []
            x, subs = coupled_run(P, dt, amp, rise, xs)
            err = np.max(np.abs(np.array(xs) - ref))
            print(f"| {drive} | coupled | {dt:.0e} | {err * 1e9:.3f} | {x * 1e6:.5f} | {subs / 2:.1f} |", flush=True)


def engine_x1(mu_k: float, dt: float, amp: float, rise: float) -> float:
    w = idm_rs.Triangle(amplitude=amp, rise=rise, fall=T_END - rise, delay=0.0)
    return idm_rs.simulate(idm_rs.Params(mu_k=mu_k), w, t_end=T_END, dt=dt, model="lps").final_position


def main() -> None:
    for amp, rise in ((80.0, 0.5e-3), (150.0, 0.1e-3)):
        ref = engine_x1(P["mu_k"], 1e-8, amp, rise)
        dref = (engine_x1(P["mu_k"] * (1 + 1e-6), 1e-8, amp, rise) - ref) / (P["mu_k"] * 1e-6)
        try:
            fit = f"{engine_x1(P['mu_k'], 2e-7, amp, rise) * 1e6:.5f} um"
        except idm_rs.DivergenceError:
            fit = "diverges"
        print(f"{amp:.0f} V, rise {rise * 1e3:.1f} ms: engine RK4 1e-8 s x1 = {ref * 1e6:.5f} um, "
              f"dx1/dmu_k = {dref:.4e} m; engine RK4 2e-7 s: {fit}")
        for dt in (2e-7, 1e-7):
            x, subs = split_run(P, dt, amp, rise)
            ds = []
            for h in (1e-3, 1e-6, 1e-9):
                q = dict(P, mu_k=P["mu_k"] * (1 + h))
                ds.append(f"{(split_run(q, dt, amp, rise)[0] - x) / (P['mu_k'] * h):.4e}")
            print(f"  split {dt:.0e} s: x1 = {x * 1e6:.5f} um (Fh sub-steps {subs:.1f} per half step), "
                  f"dx1/dmu_k at h = 1e-3, 1e-6, 1e-9: {', '.join(ds)}", flush=True)
        x = coupled_run(P, 1e-6, amp, rise, [])[0]
        ds = []
        for h in (1e-3, 1e-6, 1e-9):
            q = dict(P, mu_k=P["mu_k"] * (1 + h))
            ds.append(f"{(coupled_run(q, 1e-6, amp, rise, [])[0] - x) / (P['mu_k'] * h):.4e}")
        print(f"  coupled 1e-6 s: x1 = {x * 1e6:.5f} um, dx1/dmu_k at h = 1e-3, 1e-6, 1e-9: {', '.join(ds)}",
              flush=True)


if __name__ == "__main__":
    import sys

    trajectory() if "--trajectory" in sys.argv[1:] else main()
