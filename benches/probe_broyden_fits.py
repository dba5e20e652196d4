"""Probe: a local fit whose Jacobian is exact only every other step, Broyden-updated between.

    python benches/probe_broyden_fits.py CASE_DIR [CASE_DIR ...] [--nfev 12] [--every 2]
    python benches/probe_broyden_fits.py CASE_DIR [CASE_DIR ...] --diagnose [--every 2]

For each recording, the calibrated subset is fitted from the nominal values as given, as the
diagnosis's local fits are (trust-region reflective, bounded, scipy), twice in turn: with the
package's `fit` (an exact Jacobian at every accepted point: the engine's derivative passes, or
forward differences where a fast slip is beyond the friction state's stability limit at the fit
step) and with a variant whose Jacobian is exact at the start, after a rejected trial step and
after `--every` - 1 rank-one (Broyden) updates (with `--ratio`, also where the last step gained
less than that share of what its linear model predicted); the variant's Jacobian at its optimum is taken
exact again (the fit's uncertainties come from it), and counted. Prints chi^2 / n, evaluations,
simulated runs and seconds of each. With --diagnose, the whole diagnosis of each recording in
turn as the package runs it and with every local fit's Jacobians updated so (scipy's solver
wrapped for the run): verdict, RMS after, seconds, simulated runs, and whether the reasons are
the same. A probe, not a test: the package is unchanged.
"""

from __future__ import annotations

import argparse
import time
from typing import Any

import numpy as np
from numpy.typing import NDArray
from scipy.optimize import least_squares

from idm_rs.diagnosis.candidates import nominal_model
from idm_rs.diagnosis.case_model import CaseSimulator, ModelSpec
from idm_rs.diagnosis.fitting import FreeParam, Objective, apply, fit, inside_bounds
from idm_rs.diagnosis.noise import estimate_noise
from idm_rs.diagnosis.problem import Problem, calibration_params
from idm_rs.diagnosis.thresholds import FTOL_CHI2
from idm_rs.io.recording import load_case


def updated_fit(obj: Objective, base: ModelSpec, free: list[FreeParam], max_nfev: int, every: int,
                ratio: float = 0.0) -> tuple[float, int, dict[str, int]]:
    """The fit of `free` from u = 0 with Broyden-updated Jacobians; (chi^2, evaluations, counts)."""
    free = inside_bounds(free)
    cache: dict[bytes, tuple[NDArray[np.float64], Any, Any]] = {}
    unbounded: set[int] = set()
    n = {"exact": 0, "updates": 0, "since_jac": 0, "run": 0}
    last: list[Any] = []

    def fun(u: NDArray[np.float64]) -> NDArray[np.float64]:
        key = u.tobytes()
        if key not in cache:
            cache.clear()
            preds, steps = obj.predict_checked(apply(base, free, u))
            cache[key] = (obj.vector(preds), preds, steps)
        n["since_jac"] += 1
        return cache[key][0]

    def exact(u: NDArray[np.float64]) -> NDArray[np.float64]:
        hit = cache.get(u.tobytes())
        _, J, _ = obj.jacobian(base, free, u, 1e-3, unbounded, at=hit[1] if hit else None,
                               at_steps=hit[2] if hit else None)
        n["exact"] += 1
        n["run"] = 0
        return J

    def jac(u: NDArray[np.float64]) -> NDArray[np.float64]:
        # more than one evaluation since the last Jacobian: a trial step was rejected
        rejected, n["since_jac"] = n["since_jac"] > 1, 0
        r = cache[u.tobytes()][0]
        du = u - last[0] if last else None
        # the last linear model's prediction of the step's gain against the gain it made
        good = True
        if last and ratio > 0.0 and du is not None:
            r0, J0 = last[1], last[2]
            predicted = float(r0 @ r0 - np.sum((r0 + J0 @ du) ** 2))
            good = predicted > 0.0 and float(r0 @ r0 - r @ r) >= ratio * predicted
        if not last or rejected or not good or n["run"] >= every - 1 or du is None or not float(du @ du) > 0.0:
            J = exact(u)
        else:
            u0, r0, J0 = last
            J = J0 + np.outer((r - r0) - J0 @ du, du) / float(du @ du)
            n["updates"] += 1
            n["run"] += 1
        last[:] = [u.copy(), r.copy(), J]
        return J

    lo = np.array([f.u_bounds()[0] for f in free])
    hi = np.array([f.u_bounds()[1] for f in free])
    sol = least_squares(fun, np.zeros(len(free)), jac=jac, bounds=(lo, hi), method="trf", x_scale=1.0,
                        max_nfev=max_nfev, xtol=1e-6, ftol=FTOL_CHI2 / max(obj.n, 1), gtol=1e-8)
    if n["run"] > 0:
        exact(np.asarray(sol.x))
    return float(sol.fun @ sol.fun), int(sol.nfev), {k: n[k] for k in ("exact", "updates")}


def updating(solver: Any, every: int) -> Any:
    """scipy's `least_squares` with a callable Jacobian made exact only at the start, after a
    rejected trial step and every `every` accepted steps, Broyden-updated between; the Jacobian
    it returns is exact (an updated one at the optimum is taken again)."""

    def wrapped(fun: Any, x0: Any, jac: Any = "2-point", **kw: Any) -> Any:
        if not callable(jac):
            return solver(fun, x0, jac=jac, **kw)
        n = {"since": 0, "run": 0}
        last: list[Any] = []

        def fun2(u: NDArray[np.float64]) -> NDArray[np.float64]:
            n["since"] += 1
            return np.asarray(fun(u))

        def jac2(u: NDArray[np.float64]) -> NDArray[np.float64]:
            rejected, n["since"] = n["since"] > 1, 0
            r = np.asarray(fun(u))  # the fit's cache holds it: no run
            du = u - last[0] if last else None
            if not last or rejected or n["run"] >= every - 1 or du is None or not float(du @ du) > 0.0:
                J, n["run"] = np.asarray(jac(u)), 0
            else:
                J = last[2] + np.outer((r - last[1]) - last[2] @ du, du) / float(du @ du)
                n["run"] += 1
            last[:] = [u.copy(), r.copy(), J]
            return J

        sol = solver(fun2, x0, jac=jac2, **kw)
        if n["run"] > 0:
            sol.jac = np.asarray(jac(np.asarray(sol.x)))
        return sol

    return wrapped


def diagnose_both(case: str, every: int) -> None:
    """The diagnosis of `case` as the package runs it, then with updated Jacobians."""
    import scipy.optimize

    import idm_rs

    plain = scipy.optimize.least_squares
    rows = []
    for variant in ("exact", "updated"):
        scipy.optimize.least_squares = plain if variant == "exact" else updating(plain, every)
        t = time.perf_counter()
        try:
            d = idm_rs.diagnose(case, progress=False)
        finally:
            scipy.optimize.least_squares = plain
        s = time.perf_counter() - t
        rows.append((variant, d, s))
        print(f"| {case.rstrip('/').split('/')[-1]} | {variant} | {d.verdict} | {d.rms_after / d.noise.sigma:.3f} | "
              f"{s:.0f} | {d.simulations} |", flush=True)
    print(f"reasons equal: {rows[0][1].reason == rows[1][1].reason}; {rows[1][2] / rows[0][2]:.2f} x the seconds")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("cases", nargs="+")
    ap.add_argument("--nfev", type=int, default=12, help="the fit's evaluations (default 12, the polish's)")
    ap.add_argument("--every", type=int, default=2, help="an exact Jacobian every this many (default 2)")
    ap.add_argument("--ratio", type=float, default=0.0,
                    help="also exact where the last step gained less than this share of what its linear model "
                         "predicted (default 0: off)")
    ap.add_argument("--diagnose", action="store_true", help="the whole diagnosis, as run and with updated Jacobians")
    a = ap.parse_args()
    if a.diagnose:
        print("| recording | fit | verdict | RMS after / noise | s | simulated runs |")
        print("|---|---|---|---|---|---|")
        for case in a.cases:
            diagnose_both(case, a.every)
        return
    print("| recording | n | fit | chi2 / n | evaluations | runs | s | Jacobians exact / updated |")
    print("|---|---|---|---|---|---|---|---|")
    for case in a.cases:
        rec = load_case(case)
        noise = estimate_noise(rec)
        sim = CaseSimulator(rec)
        pb = Problem(rec, noise, sim, Objective(rec, sim, noise.sigma), None)
        nom = nominal_model(pb)
        free = calibration_params(nom.params)
        for variant in ("exact", "updated", "exact", "updated"):
            t, e0 = time.perf_counter(), sim.evaluations
            if variant == "exact":
                r = fit(pb.obj, nom.spec, free, max_nfev=a.nfev)
                chi2, nfev, counts = r.chi2, r.nfev, "every step"
            else:
                chi2, nfev, c = updated_fit(pb.obj, nom.spec, free, a.nfev, a.every, a.ratio)
                counts = f"{c['exact']} / {c['updates']}"
            print(f"| {case.rstrip('/').split('/')[-1]} | {pb.obj.n} | {variant} | {chi2 / pb.obj.n:.4f} | {nfev} | "
                  f"{sim.evaluations - e0} | {time.perf_counter() - t:.1f} | {counts} |", flush=True)


if __name__ == "__main__":
    main()
