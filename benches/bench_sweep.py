"""Sweep throughput: the same 256 sweep points through idm-rs (each method with its lanes' vector
code as the processor allows and forced to scalar dispatch), a
numba RK4 ``prange`` sweep, and ``scipy.integrate.solve_ivp`` (LSODA with a numba right-hand side,
on a sample of points).

The grid is the issue's: m2/m1 in linspace(0.25, 2, 16) x V in linspace(40, 120, 16), LPS, the
paper case (Triangle(V, 0.5e-3, 9.5e-3), 10 ms from rest, Table 1, normal force
(m1+m2+mPE) g derived per point). Accuracy is max |x1(10 ms) - reference| over the points, the
reference being idm-rs RK4 at dt = 1e-8 s on every point (computed once, about 1e6 steps per
point, and cached in ``benches/.cache/ref_1e-8.npz``).

Printed: a table of method, wall time, points/s, the ratio to the numba RK4 sweep, the largest
error against the reference, and idm-rs's parallel efficiency (time on 1 thread / time on
``--threads`` threads / ``--threads``); then how many points diverge with RK4 at dt = 1e-7 s
(numba, which has no detection or retry: its NaN/inf results, and its finite results more than
1 nm off the reference; idm-rs with ``retries=0``: status 3).

Each timing is end to end (setup, the batch, the xarray Dataset); a run under 15 s is repeated
(``--repeats``, best kept). numba's kernel is compiled (or loaded from its cache) before timing.

    python benches/bench_sweep.py [--threads 2] [--repeats 3] [--models lps,dps] [--json PATH]
    python benches/bench_sweep.py --million [--size 1000] [--method auto] [--json PATH]

``--million`` runs only the large LPS sweep (``--size`` x ``--size`` points of m2/m1 x V over
the same ranges; 1000 x 1000 by default) with the chosen idm-rs method, and records its wall
time, rate, statuses and peak memory (``resource.getrusage(...).ru_maxrss``).
"""

from __future__ import annotations

import argparse
import functools
import os
import sys

# numba's thread pool is sized from the environment at import; --threads caps it afterwards.
os.environ.setdefault("NUMBA_NUM_THREADS", str(max(2, os.cpu_count() or 2)))

import json
import platform
import resource
import time
from pathlib import Path

import numpy as np
import xarray  # noqa: F401  (imported before any timing: sweep() returns an xarray Dataset)

import idm_rs

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))

T_END = 10e-3  # s
RISE, FALL = 0.5e-3, 9.5e-3  # s
REF_DT = 1e-8  # s
RK4_DT = 5e-8  # s
DIVERGE_DT = 1e-7  # s
#: idm-rs adaptive settings timed on the 256-point grid: (method, rtol = atol)
ADAPTIVE_CASES = (("dopri5", 1e-6), ("dopri5", 3e-7), ("rodas4", 1e-5), ("rodas4", 3e-6), ("auto", None))
CACHE_DIR = HERE / ".cache"
TARGET_ERR = 1e-9  # m
LSODA_SAMPLE = ((0, 15), (3, 12), (8, 8), (15, 0))  # (mass_ratio index, voltage index)


def grid(n: int = 16) -> dict[str, np.ndarray]:
    return {"mass_ratio": np.linspace(0.25, 2.0, n), "voltage": np.linspace(40.0, 120.0, n)}


def load_average() -> tuple[float, float, float]:
    return os.getloadavg()


def run_idm_rs(g, *, method: str, dt: float, tol: float = 1e-7, threads: int, retries: int = 2,
               progress: bool = False, model: str = "lps"):
    """One idm-rs sweep of grid ``g`` (``model`` "lps" or "dps" with n = 4); returns (wall time [s],
    Dataset). ``dt`` is RK4's step; the adaptive methods start at 1e-8 s."""
    t0 = time.perf_counter()
    step = dict(dt=dt) if method == "rk4" else dict(first_step=1e-8)
    ds = idm_rs.sweep(
        idm_rs.Params(), idm_rs.Triangle(80.0, RISE, FALL), g, t_end=T_END, model=model, n_elements=4,
        method=method, rtol=tol, atol=tol, retries=retries, threads=threads, progress=progress, **step,
    )
    return time.perf_counter() - t0, ds


def best_time(fn, repeats: int, long: float = 15.0):
    """Call ``fn()`` (returning (wall, result)); if it took under ``long`` s, call it again up to
    ``repeats`` times in all and keep the fastest. Returns (best wall, result, all walls)."""
    wall, res = fn()
    walls = [wall]
    if wall < long:
        for _ in range(repeats - 1):
            w, res = fn()
            walls.append(w)
    return min(walls), res, walls


def grid_points(g):
    """Parameter dicts (normal force resolved) and breakpoints of every point, in the sweep's
    flat (C) order: mass_ratio outer, voltage inner."""
    p0 = idm_rs.Params()
    points, bps = [], []
    for r in g["mass_ratio"]:
        pd = p0.replace(m2=float(r) * p0.m1).to_dict()
        for v in g["voltage"]:
            points.append(pd)
            bt, bv = idm_rs.Triangle(float(v), RISE, FALL).breakpoints()
            bps.append((bt, bv))
    return points, bps


def reference(g, threads: int, model: str = "lps") -> np.ndarray:
    """x1(10 ms) [m] of every point, idm-rs RK4 at dt = 1e-8 s (cached per model)."""
    key = np.concatenate([g["mass_ratio"], g["voltage"], [T_END, REF_DT]])
    cache = CACHE_DIR / ("ref_1e-8.npz" if model == "lps" else f"ref_{model}4_1e-8.npz")
    if cache.exists():
        with np.load(cache) as z:
            same_key = z["key"].shape == key.shape and np.array_equal(z["key"], key)
            if same_key and str(z["version"]) == idm_rs.__version__:
                print(f"reference: {cache} (idm-rs RK4, dt = {REF_DT:g} s)")
                return z["final_position"]
    print(f"reference: computing idm-rs RK4 at dt = {REF_DT:g} s on {g['mass_ratio'].size * g['voltage'].size} points "
          f"(once; cached to {cache})", flush=True)
    wall, ds = run_idm_rs(g, method="rk4", dt=REF_DT, threads=threads, retries=3, progress=True, model=model)
    status = ds["status"].values
    if not np.all((status == 1) | (status == 2)):
        raise RuntimeError(f"reference: {int(np.sum(status == 3))} points diverged even at dt = {REF_DT:g} s")
    x = ds["final_position"].values.ravel()
    cache.parent.mkdir(parents=True, exist_ok=True)
    np.savez(cache, key=key, final_position=x, status=status.ravel(), dt_used=ds["dt_used"].values.ravel(),
             version=idm_rs.__version__, wall_time_s=wall)
    print(f"reference: {wall:.1f} s, statuses {np.bincount(status.ravel(), minlength=4).tolist()}")
    return x


# --- scipy LSODA with a numba right-hand side -----------------------------------------------------


def lsoda_point(p: dict, bt: np.ndarray, bv: np.ndarray, rtol: float, atol_scale: float):
    """x1(10 ms) [m] of one point with ``solve_ivp(method="LSODA")``, the right-hand side the numba
    baseline's ``_rhs`` (jitted), integrated piece by piece between the input's breakpoints (where
    dV/dt jumps). ``atol`` is ``atol_scale`` times each state's scale (positions d33 V, velocities
    d33 V / rise, g d33 V, Fh the static friction, h d33 V). Returns (x1, rhs evaluations)."""
    from scipy.integrate import solve_ivp

    import numba_baseline as nb

    args = nb.prepare(p, "lps")
    nn = args[0]
    rhs = _numba_ivp_rhs()
    x_scale = p["d33"] * max(abs(bv).max(), 1.0)
    scale = np.concatenate([np.full(nn, x_scale), np.full(nn, x_scale / RISE), [x_scale],
                            [p["mu_s"] * p["normal_force"]], [x_scale]])
    y = np.zeros(2 * nn + 3)
    nfev = 0
    edges = [0.0, *[t for t in bt if 0.0 < t < T_END], T_END]
    for a, b in zip(edges[:-1], edges[1:]):
        seg = int(np.searchsorted(bt, a, side="right") - 1)
        slope = (bv[seg + 1] - bv[seg]) / (bt[seg + 1] - bt[seg]) if 0 <= seg < len(bt) - 1 else 0.0
        v_a = float(np.interp(a, bt, bv))
        sol = solve_ivp(rhs, (a, b), y, method="LSODA", rtol=rtol, atol=atol_scale * scale,
                        args=(a, v_a, slope, *args))
        if sol.status != 0:
            raise RuntimeError(f"LSODA failed: {sol.message}")
        y = sol.y[:, -1]
        nfev += sol.nfev
    return float(y[0]), nfev


_RHS = None


def _numba_ivp_rhs():
    global _RHS
    if _RHS is None:
        from numba import njit

        import numba_baseline as nb

        @njit(cache=False, fastmath=False, error_model="numpy")
        def rhs(t, y, t0, v0, slope, nn, minv_k, minv_c, minv_main, minv_weight, prm, delta_is_two, n_is_one):
            dy = np.empty_like(y)
            nb._rhs(y, v0 + slope * (t - t0), slope, nn, minv_k, minv_c, minv_main, minv_weight, prm,
                    delta_is_two, n_is_one, dy)
            return dy

        _RHS = rhs
    return _RHS


# --- the benchmark -------------------------------------------------------------------------------


def bench_256(a, model: str = "lps") -> dict:
    """The 256-point grid with ``model`` ("lps", or "dps" with n = 4); the LSODA sample and the
    divergence count only for the LPS."""
    import numba

    import numba_baseline as nb

    numba.set_num_threads(a.threads)
    g = grid(16)
    n = g["mass_ratio"].size * g["voltage"].size
    ref = reference(g, a.threads, model)
    points, bps = grid_points(g)
    rows = []

    every = slice(None)

    def err(x: np.ndarray, idx=every) -> float:
        d = np.abs(np.asarray(x).ravel() - ref[idx])
        return float(np.nanmax(d)) if np.isfinite(d).any() else float("nan")

    # numba RK4 prange (compile first, on a few steps)
    nb.sweep_x1(points[:2], bps[:2], t_end=1e-6, dt=RK4_DT)

    def numba_run(dt):
        def fn():
            t0 = time.perf_counter()
            x = nb.sweep_x1(points, bps, model, t_end=T_END, dt=dt)
            return time.perf_counter() - t0, x
        return fn

    print(f"numba RK4 prange, dt = {RK4_DT:g} s, {a.threads} threads ...", flush=True)
    wall, x_nb, walls = best_time(numba_run(RK4_DT), a.repeats)
    numba_rate = n / wall
    rows.append(dict(method="numba RK4 prange", setting=f"dt = {RK4_DT:g} s", threads=a.threads, wall_s=wall,
                     walls_s=walls, points=n, points_per_s=numba_rate, max_err_m=err(x_nb),
                     diverged=int(np.sum(~np.isfinite(x_nb)))))

    idm_cases = [("idm-rs rk4", "rk4", RK4_DT, 1e-7, f"dt = {RK4_DT:g} s")]
    for method, tol in ADAPTIVE_CASES:
        if method == "auto":
            m, t, _ = idm_rs.core.methods.AUTO
            idm_cases.append(("idm-rs auto", "auto", RK4_DT, t, f"= {m} {t:g}"))
        else:
            idm_cases.append((f"idm-rs {method}", method, RK4_DT, tol, f"rtol = atol = {tol:g}"))
    for label, method, dt, tol, setting in idm_cases:
        print(f"{label} ({setting}), {a.threads} threads ...", flush=True)
        case = dict(method=method, dt=dt, tol=tol, model=model)
        wall, ds, walls = best_time(functools.partial(run_idm_rs, g, threads=a.threads, **case), a.repeats)
        print(f"{label} ({setting}), 1 thread ...", flush=True)
        wall1, ds1, walls1 = best_time(functools.partial(run_idm_rs, g, threads=1, **case), a.repeats)
        same = all(ds[v].values.tobytes() == ds1[v].values.tobytes() for v in ds.data_vars)
        # the same run with the lanes' vector code forced to scalar (SIMD against scalar dispatch)
        level = idm_rs.core.engine.simd_level()
        print(f"{label} ({setting}), {a.threads} threads, scalar dispatch (SIMD: {level}) ...", flush=True)
        idm_rs.core.engine.set_simd_level("scalar")
        try:
            wall_sc, ds_sc, _ = best_time(functools.partial(run_idm_rs, g, threads=a.threads, **case), a.repeats)
        finally:
            idm_rs.core.engine.set_simd_level(level)
        x, x_sc = ds["final_position"].values, ds_sc["final_position"].values
        st = ds["status"].values.ravel()
        rows.append(dict(
            method=label, setting=setting, threads=a.threads, wall_s=wall, walls_s=walls, points=n,
            points_per_s=n / wall, max_err_m=err(ds["final_position"].values),
            wall_1_thread_s=wall1, walls_1_thread_s=walls1,
            parallel_efficiency=wall1 / wall / a.threads, bitwise_same_1_vs_n_threads=same,
            statuses=np.bincount(st, minlength=5).tolist(),
            mean_steps=float(ds["steps"].values.mean()),
            simd_level=level, scalar_points_per_s=n / wall_sc, simd_vs_scalar=wall_sc / wall,
            simd_scalar_max_diff_m=float(np.max(np.abs(x - x_sc))), simd_scalar_bitwise=x.tobytes() == x_sc.tobytes(),
            points_over_1nm=int(np.sum(np.abs(ds["final_position"].values.ravel() - ref) > TARGET_ERR)),
        ))
    if model != "lps":
        for r in rows:
            r["vs_numba"] = r["points_per_s"] / numba_rate
        return dict(model=model, rows=rows, divergence=None, numba_points_per_s=numba_rate)

    # scipy LSODA on a sample
    sample = [i * g["voltage"].size + j for i, j in LSODA_SAMPLE]
    print(f"scipy solve_ivp LSODA (numba rhs) on {len(sample)} points ...", flush=True)
    lsoda_point(points[0], *bps[0], a.lsoda_rtol, a.lsoda_rtol)  # compile the rhs
    xs, walls_l, nfevs = [], [], []
    for k in sample:
        t0 = time.perf_counter()
        x, nfev = lsoda_point(points[k], *bps[k], a.lsoda_rtol, a.lsoda_rtol)
        walls_l.append(time.perf_counter() - t0)
        xs.append(x)
        nfevs.append(nfev)
    per_point = float(np.mean(walls_l))
    rows.append(dict(method="scipy LSODA + numba rhs", setting=f"rtol = {a.lsoda_rtol:g}",
                     sample=[[float(g["mass_ratio"][i]), float(g["voltage"][j])] for i, j in LSODA_SAMPLE],
                     threads=1, wall_s=float(np.sum(walls_l)), points=len(sample), points_per_s=1.0 / per_point,
                     s_per_point=per_point, walls_s=walls_l, max_err_m=err(np.array(xs), np.array(sample)),
                     rhs_evaluations=nfevs))
    for r in rows:
        r["vs_numba"] = r["points_per_s"] / numba_rate

    # divergence at dt = 1e-7
    print(f"divergence at dt = {DIVERGE_DT:g} s ...", flush=True)
    x_div = nb.sweep_x1(points, bps, "lps", t_end=T_END, dt=DIVERGE_DT)
    numba_div = ~np.isfinite(x_div) | (np.abs(x_div) > 1e-3)
    numba_off = numba_div | (np.abs(x_div - ref) > TARGET_ERR)
    _, ds0 = run_idm_rs(g, method="rk4", dt=DIVERGE_DT, threads=a.threads, retries=0)
    _, ds2 = run_idm_rs(g, method="rk4", dt=DIVERGE_DT, threads=a.threads, retries=2)
    st0, st2 = ds0["status"].values.ravel(), ds2["status"].values.ravel()
    divergence = dict(
        dt_s=DIVERGE_DT, points=n, numba_diverged=int(numba_div.sum()),
        numba_diverged_or_off_by_1nm=int(numba_off.sum()),
        numba_max_err_finite_m=float(np.max(np.abs(x_div - ref)[~numba_div])),
        idm_rs_retries0_status3=int(np.sum(st0 == 3)),
        idm_rs_flags_every_numba_nan=bool(np.all(st0[numba_div] == 3)),
        idm_rs_retries0_max_err_status1_m=err(np.where(st0 == 1, ds0["final_position"].values.ravel(), np.nan)),
        idm_rs_retries2_statuses=np.bincount(st2, minlength=5).tolist(),
        idm_rs_retries2_max_err_m=err(ds2["final_position"].values),
        diverged_points=[[float(g["mass_ratio"][k // 16]), float(g["voltage"][k % 16])]
                         for k in np.flatnonzero(st0 == 3)],
    )
    return dict(model=model, rows=rows, divergence=divergence, numba_points_per_s=numba_rate)


def print_256(res: dict, threads: int) -> None:
    rows = res["rows"]
    name = "LPS" if res["model"] == "lps" else "DPS (n = 4)"
    print()
    print(f"256-point {name} sweep (m2/m1 x V, 16 x 16), paper case 10 ms, {threads} threads; "
          "error vs idm-rs RK4 dt = 1e-8 s")
    head = (f"{'method':<26}{'setting':<22}{'wall [s]':>9}{'points/s':>10}{'vs numba':>10}{'steps/pt':>10}"
            f"{'max|dx1| [m]':>14}{'> 1 nm':>8}{'par. eff.':>10}")
    print(head)
    print("-" * len(head))
    for r in rows:
        eff = f"{r['parallel_efficiency'] * 100:.0f} %" if "parallel_efficiency" in r else "-"
        steps = f"{r['mean_steps']:.0f}" if "mean_steps" in r else "-"
        over = str(r["points_over_1nm"]) if "points_over_1nm" in r else "-"
        print(f"{r['method']:<26}{r['setting']:<22}{r['wall_s']:>9.2f}{r['points_per_s']:>10.1f}{r['vs_numba']:>10.2f}"
              f"{steps:>10}{r['max_err_m']:>14.2e}{over:>8}{eff:>10}")
    for r in rows:
        if "LSODA" in r["method"]:
            print(f"  LSODA: {r['s_per_point']:.3f} s per point, one thread (mean over {r['points']} points "
                  f"(m2/m1, V) = {', '.join(f'({m:.3g}, {v:.3g})' for m, v in r['sample'])}; "
                  f"{int(np.mean(r['rhs_evaluations']))} rhs evaluations per point); its wall [s] is the sum")
        if "parallel_efficiency" in r:
            print(f"  {r['method']} ({r['setting']}): 1 thread {r['wall_1_thread_s']:.2f} s; mean steps/point "
                  f"{r['mean_steps']:.0f}; statuses {r['statuses']}; 1 vs {threads} threads bitwise equal: "
                  f"{r['bitwise_same_1_vs_n_threads']}")
            print(f"    {r['simd_level']} lanes {r['points_per_s']:.1f} points/s against scalar dispatch "
                  f"{r['scalar_points_per_s']:.1f} ({r['simd_vs_scalar']:.2f}x); final positions "
                  + ("bitwise equal" if r["simd_scalar_bitwise"]
                     else f"differ by at most {r['simd_scalar_max_diff_m']:.1e} m"))
    d = res["divergence"]
    if d is None:
        return
    print(f"RK4 at dt = {d['dt_s']:g} s on {d['points']} points:")
    print(f"  numba: NaN/inf on {d['numba_diverged']}; NaN/inf or > 1 nm off the reference on "
          f"{d['numba_diverged_or_off_by_1nm']} (largest finite error {d['numba_max_err_finite_m']:.2e} m)")
    print(f"  idm-rs, retries=0: {d['idm_rs_retries0_status3']} flagged diverged (status 3; every numba NaN among "
          f"them: {d['idm_rs_flags_every_numba_nan']}); largest error of the rest "
          f"{d['idm_rs_retries0_max_err_status1_m']:.2e} m")
    print(f"  idm-rs, retries=2: statuses {d['idm_rs_retries2_statuses']} (not run, ok, ok at dt/2^k, diverged, "
          f"invalid), largest error {d['idm_rs_retries2_max_err_m']:.2e} m")


def bench_million(a) -> dict:
    g = grid(a.size)
    n = a.size * a.size
    print(f"{n} points ({a.size} x {a.size}), idm-rs {a.method}"
          + (f" dt = {a.dt:g} s" if a.method == "rk4" else f" rtol = atol = {a.tol:g}" if a.method != "auto"
             else f" = {idm_rs.core.methods.AUTO}") + f", {a.threads} threads",
          flush=True)
    wall, ds = run_idm_rs(g, method=a.method, dt=a.dt, tol=a.tol, threads=a.threads, progress=not a.no_progress)
    maxrss_kib = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss  # KiB on Linux
    st = ds["status"].values.ravel()
    out = dict(points=n, size=a.size, method=a.method, resolved=ds.attrs["method"],
               tol=ds.attrs["rtol"] if a.method != "rk4" else None,
               dt_s=a.dt, threads=a.threads, wall_s=wall, points_per_s=n / wall,
               peak_rss_mib=maxrss_kib / 1024, statuses=np.bincount(st, minlength=5).tolist(),
               complete=int(ds.attrs["complete"]), mean_steps=float(ds["steps"].values.mean()))
    print(f"wall time {wall:.1f} s ({n / wall:.0f} points/s), peak memory (ru_maxrss) {maxrss_kib / 1024:.0f} MiB, "
          f"statuses {out['statuses']} (not run, ok, ok at dt/2^k, diverged, invalid)")
    if a.save:
        from idm_rs.apps.cli_files import write_sweep_netcdf

        write_sweep_netcdf(ds, Path(a.save))
        print(f"wrote {a.save}")
    return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--threads", type=int, default=2, help="threads for idm-rs and numba (default: 2)")
    ap.add_argument("--repeats", type=int, default=3, help="timed runs of anything under 15 s (best kept)")
    ap.add_argument("--lsoda-rtol", type=float, default=1e-7,
                    help="LSODA rtol (atol = rtol x each state's scale; default: 1e-7)")
    ap.add_argument("--json", metavar="PATH", help="also write the numbers to this JSON file")
    ap.add_argument("--million", action="store_true", help="run only the large sweep (see --size)")
    ap.add_argument("--size", type=int, default=1000, help="--million: grid of SIZE x SIZE points (default 1000)")
    ap.add_argument("--models", default="lps,dps", help="256-point grid: lps, dps or both (default: lps,dps)")
    ap.add_argument("--method", choices=idm_rs.core.methods.METHODS, default="auto", help="--million: idm-rs method")
    ap.add_argument("--tol", type=float, default=1e-7, help="--million: adaptive rtol = atol (default 1e-7)")
    ap.add_argument("--dt", type=float, default=RK4_DT, help="--million: rk4 step [s]")
    ap.add_argument("--save", metavar="FILE.nc", help="--million: save the sweep as netCDF")
    ap.add_argument("--no-progress", action="store_true", help="--million: no progress bar")
    a = ap.parse_args(argv)

    load_before = load_average()
    print(f"load average before: {load_before[0]:.2f} {load_before[1]:.2f} {load_before[2]:.2f} "
          f"({os.cpu_count()} CPUs)")
    t0 = time.perf_counter()
    if a.million:
        res = bench_million(a)
    else:
        res = {m: bench_256(a, m) for m in a.models.split(",")}
        for r in res.values():
            print_256(r, a.threads)
    load_after = load_average()
    print(f"load average after: {load_after[0]:.2f} {load_after[1]:.2f} {load_after[2]:.2f}; "
          f"benchmark took {time.perf_counter() - t0:.0f} s")

    if a.json:
        import numba
        import scipy

        out = {
            "benchmark": "sweep_million" if a.million else "sweep_256",
            "case": {"model": "lps", "waveform": f"Triangle(V, {RISE:g}, {FALL:g})", "t_end_s": T_END,
                     "mass_ratio": [0.25, 2.0], "voltage": [40.0, 120.0],
                     "normal_force": "(m1+m2+mPE) g per point", "reference": f"idm-rs rk4 dt = {REF_DT:g} s"},
            "environment": {"python": platform.python_version(), "numpy": np.__version__, "numba": numba.__version__,
                            "scipy": scipy.__version__, "idm_rs": idm_rs.__version__,
                            "machine": platform.machine(), "processor": platform.processor(),
                            "platform": platform.platform(), "cpus": os.cpu_count(),
                            "load_average_before": load_before, "load_average_after": load_after},
            "results": res,
        }
        Path(a.json).write_text(json.dumps(out, indent=2) + "\n")
        print(f"wrote {a.json}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
