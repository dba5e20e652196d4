"""Issue 54's prototype: steps and right-hand-side work per point of candidate integrators at the
sweep's promise (x1 at t_end within 1 nm of RK4 at dt = 1e-8 s), before anything is built.

The right-hand side is the engine's own: the C function the GPU kernel compiles, generated from
the Rust model (`engine.kernel_program`), built here with the C compiler and called through
ctypes, so every candidate integrates the same physics as the engine. Each run goes segment by
segment of the piecewise-linear input (landing on every breakpoint, as the engine's adaptive
methods do), with the engine's error scales (atol times each state's natural scale, g left out).

Candidates: scipy's RK45 (Dormand-Prince 5(4): today's explicit method, the baseline), DOP853
(a higher-order explicit pair), Radau (implicit, order 5), BDF and LSODA; and exprb32, an
exponential Rosenbrock method of order 3(2) (Hochbruck, Ostermann & Schweitzer 2009) written
here: the step's Jacobian (finite differences of the C right-hand side) and phi functions of the
small dense matrix (scipy's expm of the augmented matrix), exact for the linearised ringing.
For each, the loosest tolerance in a ladder that keeps the point within 1 nm, and there: the
accepted steps, the right-hand-side evaluations (Jacobians by finite differences included; the
count an analytic Jacobian would need is reported beside), the Jacobians and the matrix
exponentials.

    python benches/proto_fewer_steps.py [--models lps] [--json PATH]
"""

from __future__ import annotations

import argparse
import ctypes
import hashlib
import json
import os
import shutil
import subprocess
import tempfile
import time
from pathlib import Path
from typing import Any, Callable

import numpy as np
from scipy.integrate import solve_ivp
from scipy.linalg import expm

import idm_rs
from idm_rs.core import engine
from idm_rs.core.batch import Structure, param_row
from idm_rs.gpu.backend import program

#: the points: the paper's device and the five corners of bench_auto_corners.py at their extremes
POINTS = {
    "paper (m2/m1 1, 80 V)": dict(mass_ratio=None, voltage=80.0),
    "light weight, high voltage": dict(mass_ratio=0.25, voltage=120.0),
    "heavy weight, low voltage": dict(mass_ratio=2.0, voltage=40.0),
    "light weight, low voltage": dict(mass_ratio=0.25, voltage=40.0),
    "heavy weight, high voltage": dict(mass_ratio=2.0, voltage=120.0),
    "stiff contact (fric_alpha 2e11)": dict(mass_ratio=None, voltage=80.0, fric_alpha=2e11),
}
LADDER = (1e-2, 3e-3, 1e-3, 3e-4, 1e-4, 3e-5, 1e-5, 3e-6, 1e-6, 3e-7, 1e-7, 3e-8, 1e-8, 3e-9, 1e-9)
T_END = 10e-3
NM = 1e-9


class Rhs:
    """The engine's right-hand side for one point, compiled from its generated C, with counters."""

    def __init__(self, params: idm_rs.Params, model: str, n_elements: int) -> None:
        cfg = Structure(model, n_elements, True).config(method="rk4", dt=1e-8)
        spec, consts = program(cfg, np.asarray([param_row(params)], dtype=float),
                               np.zeros((1, len(engine.effect_names()))))
        src = ("#include <math.h>\n#define IDM_HD\n#define IDM_CK(c, k) ((c)[k])\n#define IDM_INF INFINITY\n"
               "#define IDM_NAN NAN\n#define IDM_SIN(x) sin(x)\n#define IDM_COS(x) cos(x)\n" + spec.layout + spec.rhs)
        self.dll = _compiled(src)
        self.dll.idm_rhs.restype = ctypes.c_double
        d, p = ctypes.c_double, np.ctypeslib.ndpointer(dtype=np.float64, flags="C_CONTIGUOUS")
        self.dll.idm_rhs.argtypes = [p, d, d, d, p, p]
        self.c = np.ascontiguousarray(consts[0])
        self.dim = int(spec.layout.split("#define IDM_DIM ")[1].split()[0])
        kinds = [int(k) for k in spec.layout.split("IDM_SCALE_KINDS {")[1].split("}")[0].split(",")]
        n = len(self.c)
        stroke_per_v, omega, fs = self.c[n - 3], self.c[n - 2], self.c[n - 1]
        self.kinds, self.parts = kinds, (stroke_per_v, omega, fs)
        self.calls = 0

    def scales(self, v_max: float) -> np.ndarray:
        """Model::state_scales: the error norm's scale of each component (g: out, as inf)."""
        stroke_per_v, omega, fs = self.parts
        stroke = max(stroke_per_v * abs(v_max), 1e-9)
        by_kind = {0: np.inf, 1: stroke, 2: stroke * omega, 3: fs, 4: max(abs(v_max), 1.0)}
        return np.array([by_kind[k] for k in self.kinds])

    def __call__(self, t: float, volt: float, dvolt: float, y: np.ndarray) -> np.ndarray:
        self.calls += 1
        dy = np.empty(self.dim)
        self.dll.idm_rhs(self.c, t, volt, dvolt, np.ascontiguousarray(y, dtype=float), dy)
        return dy


def _compiled(src: str) -> ctypes.CDLL:
    cc = os.environ.get("CC") or shutil.which("cc") or shutil.which("gcc")
    if cc is None:
        raise SystemExit("no C compiler")
    lib = Path(tempfile.gettempdir()) / f"idm_rhs_{hashlib.sha256(src.encode()).hexdigest()[:16]}.so"
    if not lib.exists():
        subprocess.run([cc, "-O2", "-shared", "-fPIC", "-x", "c", "-", "-o", str(lib), "-lm"], input=src, text=True,
                       check=True)
    return ctypes.CDLL(str(lib))


def segments(w: idm_rs.Triangle, t_end: float) -> list[tuple[float, float, float, float]]:
    """(t_a, t_b, V at t_a, slope [V/s]) of each piece of the input up to t_end."""
    t, v = (np.asarray(a, dtype=float) for a in w.breakpoints())
    out = []
    for k in range(len(t) - 1):
        if t[k] >= t_end:
            break
        out.append((t[k], min(t[k + 1], t_end), v[k], (v[k + 1] - v[k]) / (t[k + 1] - t[k])))
    if t[-1] < t_end:
        out.append((t[-1], t_end, v[-1], 0.0))
    return out


def run_scipy(rhs: Rhs, segs: list, method: str, tol: float, scales: np.ndarray) -> dict[str, Any]:
    y = np.zeros(rhs.dim)
    atol = tol * np.where(np.isfinite(scales), scales, 1e30)
    steps = njev = nlu = 0
    rhs.calls = 0
    for ta, tb, va, s in segs:
        def f(t: float, yy: np.ndarray, va: float = va, s: float = s, ta: float = ta) -> np.ndarray:
            return rhs(t, va + s * (t - ta), s, yy)

        r = solve_ivp(f, (ta, tb), y, method=method, rtol=tol, atol=atol)
        if r.status != 0:
            return dict(ok=False)
        y = r.y[:, -1]
        steps += r.t.size - 1
        njev += int(r.njev)
        nlu += int(r.nlu)
    return dict(ok=True, x1=float(y[0]), steps=steps, rhs=rhs.calls, jacobians=njev, expm=0, lu=nlu,
                rhs_analytic_jacobian=rhs.calls - njev * rhs.dim + njev * 2)


def _autonomous(rhs: Rhs, ta: float, va: float, s: float) -> Callable[[np.ndarray], np.ndarray]:
    """The right-hand side on the segment starting at ta (input va + s (t - ta)) as an autonomous
    system in (y, t): t' = 1."""
    def f(zz: np.ndarray) -> np.ndarray:
        return np.append(rhs(zz[-1], va + s * (zz[-1] - ta), s, zz[:-1]), 1.0)

    return f


def _jacobian(f: Callable[[np.ndarray], np.ndarray], z: np.ndarray, fz: np.ndarray, sc: np.ndarray) -> np.ndarray:
    """df/dz by forward differences, each component stepped by 1e-7 of its size or scale."""
    m = z.size
    jac = np.empty((m, m))
    for j in range(m):
        dz = 1e-7 * max(abs(z[j]), sc[j] if np.isfinite(sc[j]) else 1e-6)
        zp = z.copy()
        zp[j] += dz
        jac[:, j] = (f(zp) - fz) / dz
    return jac


def run_exprb32(rhs: Rhs, segs: list, tol: float, scales: np.ndarray) -> dict[str, Any]:
    """exprb32 with its embedded error estimate (the order-3 correction 2 h phi3(hJ) D2), on the
    autonomous system (y, t); the Jacobian by forward differences of the C right-hand side."""
    m = rhs.dim + 1
    z = np.zeros(m)
    sc = np.append(np.where(np.isfinite(scales), scales, np.inf), np.inf)
    counted = np.isfinite(sc)
    steps = jacs = exps = 0
    rhs.calls = 0
    h = 1e-8
    for ta, tb, va, s in segs:
        f = _autonomous(rhs, ta, va, s)
        z[-1] = ta
        while z[-1] < tb * (1 - 1e-15):
            h = min(h, tb - z[-1])
            fz = f(z)
            jac = _jacobian(f, z, fz, sc)
            jacs += 1
            while True:
                big = np.zeros((m + 3, m + 3))
                big[:m, :m] = h * jac
                big[m, m + 1] = big[m + 1, m + 2] = 1.0
                big[:m, m] = fz
                u2 = z + h * expm(big)[:m, m]
                d2 = f(u2) - fz - jac @ (u2 - z)
                big[:m, m] = d2
                corr = 2.0 * h * expm(big)[:m, m + 2]
                exps += 2
                z1 = u2 + corr
                tolv = tol * sc[counted] + tol * np.maximum(np.abs(z[counted]), np.abs(z1[counted]))
                err = float(np.sqrt(np.mean((corr[counted] / tolv) ** 2)))
                if err <= 1.0 and np.all(np.isfinite(z1)):
                    z = z1
                    steps += 1
                    h *= min(5.0, 0.9 * err ** (-1 / 3)) if err > 0 else 5.0
                    break
                h *= max(0.1, 0.9 * err ** (-1 / 3)) if np.isfinite(err) else 0.1
                if h < 1e-15:
                    return dict(ok=False)
        z[-1] = tb
    return dict(ok=True, x1=float(z[0]), steps=steps, rhs=rhs.calls, jacobians=jacs, expm=exps,
                rhs_analytic_jacobian=rhs.calls - jacs * m + jacs * 2)


def unit_costs(model: str = "lps") -> dict[str, float]:
    """What one right-hand side and one dense matrix product of the phi functions' size cost in C
    on this machine [ns] (-O2, one core): the exchange rate between the candidates' counts. An
    expm by Pade 13 with scaling and squaring costs about 6 products, a solve (~3 products) and
    one product per squaring: 13 products is taken for it (|hJ| up to 2^4 times Pade's range)."""
    n = 4 if model == "dps" else 1
    cfg = Structure(model, n, True).config(method="rk4", dt=1e-8)
    spec, consts = program(cfg, np.asarray([param_row(idm_rs.Params())], dtype=float),
                           np.zeros((1, len(engine.effect_names()))))
    dim = int(spec.layout.split("#define IDM_DIM ")[1].split()[0])
    m = dim + 1 + 3
    src = ("#include <math.h>\n#include <time.h>\n#define IDM_HD static\n#define IDM_CK(c, k) ((c)[k])\n"
           "#define IDM_INF INFINITY\n#define IDM_NAN NAN\n#define IDM_SIN(x) sin(x)\n#define IDM_COS(x) cos(x)\n"
           + spec.layout + spec.rhs + f"""
static double now(void) {{ struct timespec t; clock_gettime(CLOCK_MONOTONIC, &t); return t.tv_sec + 1e-9 * t.tv_nsec; }}
double rhs_ns(const double *c, long reps) {{
    double y[IDM_DIM] = {{0}}, dy[IDM_DIM], acc = 0.0;
    y[IDM_N] = 1e-3; y[IDM_IFH] = 0.1;
    double t0 = now();
    for (long r = 0; r < reps; r++) {{
        double u = (double)(r & 1023) / 1024.0;  /* every input moves: nothing can leave the loop */
        for (int i = 0; i < IDM_DIM; i++) y[i] = 1e-7 * u * (double)(i + 1);
        y[IDM_N] = 1e-3 * (u - 0.5); y[IDM_IFH] = 0.2 * (u - 0.3);
        acc += idm_rhs(c, 1e-4 * u, 50.0 + u, 1e5, y, dy);
        for (int i = 0; i < IDM_DIM; i++) acc += dy[i];
    }}
    double t1 = now();
    return acc == 12345.0 ? -1.0 : 1e9 * (t1 - t0) / (double)reps;
}}
double matmul_ns(long reps) {{
    enum {{ M = {m} }};
    double a[M][M], b[M][M], o[M][M];
    for (int i = 0; i < M; i++) for (int j = 0; j < M; j++) {{ a[i][j] = 1e-3 * (i - j); b[i][j] = 1e-3 * (i + j); }}
    double t0 = now();
    for (long r = 0; r < reps; r++) {{
        for (int i = 0; i < M; i++)
            for (int j = 0; j < M; j++) {{
                double s = 0.0;
                for (int k = 0; k < M; k++) s += a[i][k] * b[k][j];
                o[i][j] = s;
            }}
        a[r % M][0] = o[0][r % M];
    }}
    double t1 = now();
    return o[1][1] == 12345.0 ? -1.0 : 1e9 * (t1 - t0) / (double)reps;
}}
""")
    dll = _compiled(src)
    dll.rhs_ns.restype = dll.matmul_ns.restype = ctypes.c_double
    dll.rhs_ns.argtypes = [np.ctypeslib.ndpointer(dtype=np.float64, flags="C_CONTIGUOUS"), ctypes.c_long]
    dll.matmul_ns.argtypes = [ctypes.c_long]
    rhs = min(dll.rhs_ns(np.ascontiguousarray(consts[0]), 2_000_000) for _ in range(3))
    mm = min(dll.matmul_ns(200_000) for _ in range(3))
    return dict(model=model, rhs_ns=rhs, matmul_ns=mm, matrix_size=m, expm_ns=13 * mm, expm_in_rhs=13 * mm / rhs)


def engine_work(name: str, point: dict[str, Any], model: str = "lps") -> list[dict[str, Any]]:
    """The engine's own cost of the point, single-threaded, in right-hand-side equivalents: its
    wall time over the time of one RK4 evaluation (an RK4 run at 1e-8 s, 4 per step), for
    `auto` (which does not report how many of its steps were Rodas4's), dopri5 at auto's
    tolerance and rodas4 at 1e-5."""
    p = idm_rs.Params()
    if point.get("mass_ratio") is not None:
        p = p.replace(m2=point["mass_ratio"] * p.m1)
    if "fric_alpha" in point:
        p = p.replace(fric_alpha=point["fric_alpha"])
    w = idm_rs.Triangle(point["voltage"], 0.5e-3, 9.5e-3)
    n = 4 if model == "dps" else 1

    def best(**kw: Any) -> tuple[float, Any]:
        runs = []
        for _ in range(3):
            t0 = time.perf_counter()
            r = idm_rs.simulate(p, w, T_END, model=model, n_elements=n, save_every=10**9, **kw)
            runs.append((time.perf_counter() - t0, r))
        return min(runs, key=lambda x: x[0])

    dt = 1e-8
    while True:
        try:
            wall_rk4, ref = best(dt=dt)
            break
        except idm_rs.DivergenceError:
            dt /= 2
    per_rhs = wall_rk4 / (4 * round(T_END / dt))
    rows = []
    for label, kw in (("engine auto", dict(method="auto")), ("engine dopri5 3e-7", dict(method="dopri5", rtol=3e-7,
                      atol=3e-7)), ("engine rodas4 1e-5", dict(method="rodas4", rtol=1e-5, atol=1e-5))):
        wall, r = best(**kw)
        rows.append(dict(model=model, point=name, method=label, rhs_equivalents=round(wall / per_rhs),
                         err_m=abs(r.final_position - ref.final_position), wall_ms=round(wall * 1e3, 2)))
        print(json.dumps(rows[-1]), flush=True)
    # the engine's own Rosenbrock at its loosest tolerance that keeps the point within 1 nm
    for tol in LADDER:
        try:
            wall, r = best(method="rodas4", rtol=tol, atol=tol)
        except idm_rs.DivergenceError:
            continue
        if abs(r.final_position - ref.final_position) <= NM:
            steps = idm_rs.simulate(p, w, T_END, model=model, n_elements=n, save_every=1, method="rodas4", rtol=tol,
                                    atol=tol).t.size - 1
            rows.append(dict(model=model, point=name, method="engine rodas4, loosest within 1 nm", tol=tol,
                             steps=int(steps), rhs_equivalents=round(wall / per_rhs),
                             err_m=abs(r.final_position - ref.final_position), wall_ms=round(wall * 1e3, 2)))
            print(json.dumps(rows[-1]), flush=True)
            break
    return rows


#: Rodas5P (Steinebach 2023), in the transformed form of Hairer & Wanner's RODAS: stage inputs
#: A, stage couplings C (divided by h), gamma; the increment of the last stage is the error
RODAS5P_GAMMA = 0.21193756319429014
RODAS5P_A = [[], [3.0], [2.849394379747939, 0.45842242204463923],
             [-6.954028509809101, 2.489845061869568, -10.358996098473584],
             [2.8029986275628964, 0.5072464736228206, -0.3988312541770524, -0.04721187230404641],
             [-7.502846399306121, 2.561846144803919, -11.627539656261098, -0.18268767659942256,
              0.030198172008377946]]
RODAS5P_C = [[], [-14.155112264123755], [-17.97296035885952, -2.859693295451294],
             [147.12150275711716, -1.41221402718213, 71.68940251302358],
             [165.43517024871676, -0.4592823456491126, 42.90938336958603, -5.961986721573306],
             [24.854864614690072, -3.0009227002832186, 47.4931110020768, 5.5814197821558125, -0.6610691825249471],
             [30.91273214028599, -3.1208243349937974, 77.79954646070892, 34.28646028294783, -19.097331116725623,
              -28.087943162872662],
             [37.80277123390563, -3.2571969029072276, 112.26918849496327, 66.9347231244047, -40.06618937091002,
              -54.66780262877968, -9.48861652309627]]


def run_rodas5p(rhs: Rhs, segs: list, tol: float, scales: np.ndarray) -> dict[str, Any]:
    """Rodas5P on the autonomous system (y, t): per step one Jacobian (forward differences of the
    C right-hand side), one LU of I/(h gamma) - J, 8 stages (right-hand side and solve each); the
    last stage's increment is the error estimate (order 4 against 5)."""
    from scipy.linalg import lu_factor, lu_solve

    m = rhs.dim + 1
    z = np.zeros(m)
    sc = np.append(np.where(np.isfinite(scales), scales, np.inf), np.inf)
    counted = np.isfinite(sc)
    steps = jacs = lus = 0
    rhs.calls = 0
    h = 1e-8
    for ta, tb, va, s in segs:
        f = _autonomous(rhs, ta, va, s)
        z[-1] = ta
        while z[-1] < tb * (1 - 1e-15):
            h = min(h, tb - z[-1])
            fz = f(z)
            jac = _jacobian(f, z, fz, sc)
            jacs += 1
            while True:
                lu = lu_factor(np.eye(m) / (h * RODAS5P_GAMMA) - jac, check_finite=False)
                lus += 1
                k: list[np.ndarray] = []
                u = z.copy()
                for i in range(8):
                    if i == 0:
                        du = fz
                    else:
                        if i < 6:
                            u = z + sum(a * kj for a, kj in zip(RODAS5P_A[i], k))
                        else:
                            u = u + k[-1]
                        du = f(u)
                    rhs_i = du + sum((c / h) * kj for c, kj in zip(RODAS5P_C[i], k)) if i else du
                    k.append(lu_solve(lu, rhs_i, check_finite=False))
                z1 = u + k[-1]
                tolv = tol * sc[counted] + tol * np.maximum(np.abs(z[counted]), np.abs(z1[counted]))
                err = float(np.sqrt(np.mean((k[-1][counted] / tolv) ** 2)))
                if err <= 1.0 and np.all(np.isfinite(z1)):
                    z = z1
                    steps += 1
                    h *= min(5.0, 0.9 * err ** (-1 / 5)) if err > 0 else 5.0
                    break
                h *= max(0.1, 0.9 * err ** (-1 / 5)) if np.isfinite(err) else 0.1
                if h < 1e-15:
                    return dict(ok=False)
        z[-1] = tb
    # one Jacobian (2 right-hand sides analytic), one LU and 8 stages per attempt
    return dict(ok=True, x1=float(z[0]), steps=steps, rhs=rhs.calls, jacobians=jacs, expm=0, lu=lus,
                rhs_analytic_jacobian=rhs.calls - jacs * m + jacs * 2)


#: the prototypes written here (scipy's methods by name otherwise); proto_structured_steps.py adds its own
RUNNERS: dict[str, Callable[[Rhs, list, float, np.ndarray], dict[str, Any]]] = {
    "exprb32": run_exprb32, "rodas5p": run_rodas5p}


def measure(name: str, point: dict[str, Any], model: str, methods: list[str]) -> list[dict[str, Any]]:
    p = idm_rs.Params()
    if point.get("mass_ratio") is not None:
        p = p.replace(m2=point["mass_ratio"] * p.m1)
    if "fric_alpha" in point:
        p = p.replace(fric_alpha=point["fric_alpha"])
    w = idm_rs.Triangle(point["voltage"], 0.5e-3, 9.5e-3)
    n = 4 if model == "dps" else 1
    ref, dt_ref = None, 1e-8
    while ref is None:  # RK4 at 1e-8 s, halved where the contact is too stiff for it (as a sweep retries)
        try:
            ref = idm_rs.simulate(p, w, T_END, dt_ref, model=model, n_elements=n, save_every=10**9).final_position
        except idm_rs.DivergenceError:
            dt_ref /= 2
    auto = idm_rs.simulate(p, w, T_END, model=model, n_elements=n, method="auto", save_every=1)
    rhs = Rhs(p, model, n)
    segs, scales = segments(w, T_END), rhs.scales(point["voltage"])
    rows = [dict(model=model, point=name, method="engine auto (DP5 + Rodas4 switch)", tol=auto.rtol,
                 steps=int(auto.t.size - 1), err_m=abs(auto.final_position - ref), rk4_reference_dt=dt_ref)]
    print(json.dumps(rows[-1]), flush=True)
    for method in methods:
        for tol in LADDER:
            t0 = time.perf_counter()
            if method in RUNNERS:
                r = RUNNERS[method](rhs, segs, tol, scales)
            else:
                r = run_scipy(rhs, segs, method, tol, scales)
            if r["ok"] and abs(r["x1"] - ref) <= NM:
                rows.append(dict(model=model, point=name, method=method, tol=tol, err_m=abs(r["x1"] - ref),
                                 wall_s=round(time.perf_counter() - t0, 2),
                                 **{k: v for k, v in r.items() if k not in ("ok", "x1")}))
                print(json.dumps(rows[-1]), flush=True)
                break
        else:
            rows.append(dict(model=model, point=name, method=method, tol=None, note="no tolerance of the ladder "
                             "kept it within 1 nm"))
            print(json.dumps(rows[-1]), flush=True)
    return rows


def grid_run(model: str, size: int, tol: float, method: str, out: Path) -> None:
    """One tolerance for every point of bench_auto_corners.py's corner grids (size x size each):
    the largest error against RK4 at dt = 1e-8 s (halved where it diverges), the points beyond
    1 nm, the median steps and right-hand-side equivalents; rows appended to ``out`` (JSON lines)
    as each corner finishes, so a long run resumes by skipping what is there."""
    from bench_auto_corners import CORNERS  # the same grids

    done = {(r["model"], r["corner"], r["method"], r["tol"]) for r in
            (json.loads(line) for line in out.read_text().splitlines())} if out.exists() else set()
    n = 4 if model == "dps" else 1
    w = idm_rs.Triangle(80.0, 0.5e-3, 9.5e-3)
    for name, (axis, (a0, a1), log, (v0, v1)) in CORNERS.items():
        if (model, name, method, tol) in done:
            continue
        first = np.geomspace(a0, a1, size) if log else np.linspace(a0, a1, size)
        grid = {axis: first, "voltage": np.linspace(v0, v1, size)}
        ref = idm_rs.sweep(idm_rs.Params(), w, grid, dt=1e-8, t_end=T_END, model=model, n_elements=n, progress=False,
                           retries=3)["final_position"].values
        errs, steps, work = [], [], []
        for i, x in enumerate(first):
            for j, v in enumerate(grid["voltage"]):
                p = idm_rs.Params()
                p = p.replace(m2=x * p.m1) if axis == "mass_ratio" else p.replace(**{axis: float(x)})
                wv = idm_rs.Triangle(float(v), 0.5e-3, 9.5e-3)
                rhs = Rhs(p, model, n)
                r = run_rodas5p(rhs, segments(wv, T_END), tol, rhs.scales(float(v)))
                errs.append(abs(r["x1"] - ref[i, j]) if r["ok"] else np.inf)
                steps.append(r.get("steps", 0))
                work.append(r.get("rhs_analytic_jacobian", 0))
        e = np.asarray(errs)
        row = dict(model=model, corner=name, method=method, tol=tol, size=size, max_err_m=float(e.max()),
                   points_over_1nm=int((e > NM).sum()), median_steps=float(np.median(steps)),
                   median_rhs_equivalents=float(np.median(work)))
        print(json.dumps(row), flush=True)
        with out.open("a") as f:
            f.write(json.dumps(row) + "\n")


def sweep_grid_run(model: str, size: int, tol: float, out: Path) -> dict[str, Any]:
    """bench_sweep.py's grid (m2/m1 in linspace(0.25, 2, size) x V in linspace(40, 120, size)):
    per point the engine's `auto` (single-threaded wall, best of 3; accepted steps), the engine's
    Rodas4 at 1e-5 (its wall, its error, and its wall per accepted step: what one Rosenbrock
    step of the engine costs)
    and the Rodas5P prototype at `tol` (accepted steps, attempts, error against RK4 at 1e-8 s).
    Rodas5P's engine time is estimated as its attempts x Rodas4's time per step x 8/6 (two
    stages more per step, the Jacobian and the LU alike): what the grid's time would be with
    Rodas5P in `auto`'s place, where it is the faster of the two, point by point. Rows appended
    to `out`; returns the totals."""
    n = 4 if model == "dps" else 1
    w = idm_rs.Triangle(80.0, 0.5e-3, 9.5e-3)
    grid = {"mass_ratio": np.linspace(0.25, 2.0, size), "voltage": np.linspace(40.0, 120.0, size)}
    ref = idm_rs.sweep(idm_rs.Params(), w, grid, dt=1e-8, t_end=T_END, model=model, n_elements=n, progress=False,
                       retries=3)["final_position"].values
    rows = []
    for i, ratio in enumerate(grid["mass_ratio"]):
        for j, v in enumerate(grid["voltage"]):
            p = idm_rs.Params().replace(m2=float(ratio) * idm_rs.Params().m1)
            wv = idm_rs.Triangle(float(v), 0.5e-3, 9.5e-3)

            def best(p: idm_rs.Params = p, wv: Any = wv, **kw: Any) -> tuple[float, Any]:
                runs = []
                for _ in range(3):
                    t0 = time.perf_counter()
                    r = idm_rs.simulate(p, wv, T_END, model=model, n_elements=n, save_every=1, **kw)
                    runs.append((time.perf_counter() - t0, r))
                return min(runs, key=lambda x: x[0])

            wall_auto, ra = best(method="auto")
            wall_r4, r4 = best(method="rodas4", rtol=1e-5, atol=1e-5)
            rhs = Rhs(p, model, n)
            r5 = run_rodas5p(rhs, segments(wv, T_END), tol, rhs.scales(float(v)))
            per_step = wall_r4 / max(r4.t.size - 1, 1)
            est = r5["lu"] * per_step * 8.0 / 6.0 if r5["ok"] else np.inf
            rows.append(dict(model=model, mass_ratio=float(ratio), voltage=float(v), auto_steps=int(ra.t.size - 1),
                             auto_wall_s=wall_auto, auto_err_m=abs(ra.final_position - ref[i, j]),
                             rodas4_steps=int(r4.t.size - 1), rodas4_wall_s=wall_r4,
                             rodas4_err_m=abs(r4.final_position - ref[i, j]),
                             rodas5p_steps=r5.get("steps"), rodas5p_attempts=r5.get("lu"),
                             rodas5p_err_m=abs(r5["x1"] - ref[i, j]) if r5["ok"] else None,
                             rodas5p_wall_estimate_s=est))
    with out.open("a") as f:
        for r in rows:
            f.write(json.dumps({**r, "tol": tol}) + "\n")
    auto = np.array([r["auto_wall_s"] for r in rows])
    est = np.array([r["rodas5p_wall_estimate_s"] for r in rows])
    errs = np.array([r["rodas5p_err_m"] if r["rodas5p_err_m"] is not None else np.inf for r in rows])
    r4 = np.array([r["rodas4_wall_s"] for r in rows])
    r4_errs = np.array([r["rodas4_err_m"] for r in rows])
    return dict(model=model, tol=tol, points=len(rows), auto_total_s=float(auto.sum()),
                rodas4_total_s=float(r4.sum()), auto_or_rodas4_s=float(np.minimum(auto, r4).sum()),
                rodas4_points_over_1nm=int((r4_errs > NM).sum()), rodas4_max_err_m=float(r4_errs.max()),
                points_rodas4_faster=int((r4 < auto).sum()),
                rodas5p_total_estimate_s=float(est.sum()), best_of_both_s=float(np.minimum(auto, est).sum()),
                rodas5p_points_over_1nm=int((errs > NM).sum()), rodas5p_max_err_m=float(errs.max()),
                points_rodas5p_faster=int((est < auto).sum()),
                auto_steps_median=float(np.median([r["auto_steps"] for r in rows])),
                rodas5p_steps_median=float(np.median([r["rodas5p_steps"] or 0 for r in rows])))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--models", default="lps")
    ap.add_argument("--methods", default="RK45,DOP853,Radau,BDF,LSODA,exprb32")
    ap.add_argument("--points", default="", help="comma-separated name fragments (default: all)")
    ap.add_argument("--json", type=Path)
    ap.add_argument("--engine", action="store_true", help="the engine's own cost of each point (auto, dopri5, "
                    "rodas4) in right-hand-side equivalents, and stop")
    ap.add_argument("--grid", type=int, default=0, help="Rodas5P at one tolerance (--tol) over "
                    "bench_auto_corners.py's corner grids of this size, rows appended to --out")
    ap.add_argument("--sweep-grid", type=int, default=0, help="bench_sweep.py's grid of this size: the engine's "
                    "auto and Rodas4 against the Rodas5P prototype at --tol, point by point, rows to --out")
    ap.add_argument("--tol", type=float, default=1e-5)
    ap.add_argument("--out", type=Path, default=Path("benches/results/proto_rodas5p_grids.jsonl"))
    ap.add_argument("--costs", action="store_true", help="print the C cost of a right-hand side and of an "
                    "expm of the phi functions' size, and stop")
    a = ap.parse_args()
    if a.grid:
        import sys

        sys.path.insert(0, str(Path(__file__).parent))
        for model in a.models.split(","):
            grid_run(model, a.grid, a.tol, "rodas5p", a.out)
        return
    if a.sweep_grid:
        for model in a.models.split(","):
            print(json.dumps(sweep_grid_run(model, a.sweep_grid, a.tol, a.out)), flush=True)
        return
    if a.costs:
        for model in a.models.split(","):
            print(json.dumps(unit_costs(model)))
        return
    rows: list[dict[str, Any]] = []
    if a.engine:
        for model in a.models.split(","):
            for name, point in POINTS.items():
                rows += engine_work(name, point, model)
        if a.json:
            a.json.write_text(json.dumps(rows, indent=1))
        return
    for model in a.models.split(","):
        for name, point in POINTS.items():
            if a.points and not any(f in name for f in a.points.split(",")):
                continue
            rows += measure(name, point, model, a.methods.split(","))
            if a.json:
                a.json.write_text(json.dumps(rows, indent=1))


if __name__ == "__main__":
    main()
