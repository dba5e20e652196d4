"""Probe: a local fit whose Jacobian is exact only every other step, Broyden-updated between.

    python benches/probe_broyden_fits.py CASE_DIR [CASE_DIR ...] [--nfev 12] [--every 2]
    python benches/probe_broyden_fits.py CASE_DIR [CASE_DIR ...] --diagnose [--every 2]

For each recording, the calibrated subset is fitted from the nominal values as given, as the
diagnosis's local fits are (trust-region reflective, bounded, scipy), twice in turn with the
package's `fit`: as it runs (an exact Jacobian at every accepted point: the engine's derivative
passes, or forward differences where a fast slip is beyond the friction state's stability limit
at the fit step), and with scipy's solver wrapped so that the Jacobian is exact at the start,
after a rejected trial step and after `--every` - 1 rank-one (Broyden) updates (with `--ratio`,
also where the last step gained less than that share of what its linear model predicted); the
wrapped solver's Jacobian at the optimum is taken exact again (the fit's uncertainties come
from it), and counted. Prints chi^2 / n, evaluations, simulated runs and seconds of each. With
--diagnose, the whole diagnosis of each recording in turn as the package runs it and with every
local fit's Jacobians updated so: verdict, RMS after, seconds, simulated runs, and whether the
reasons are the same. A probe, not a test: the package is unchanged.
"""

from __future__ import annotations

import argparse
import time
from typing import Any, Optional

import numpy as np
import scipy.optimize
from numpy.typing import NDArray

from idm_rs.diagnosis.candidates import nominal_model
from idm_rs.diagnosis.case_model import CaseSimulator
from idm_rs.diagnosis.fitting import Objective, fit
from idm_rs.diagnosis.noise import estimate_noise
from idm_rs.diagnosis.problem import Problem, calibration_params
from idm_rs.io.recording import load_case


def updating(solver: Any, every: int, ratio: float = 0.0, counts: Optional[dict[str, int]] = None) -> Any:
    """scipy's `least_squares` with a callable Jacobian made exact only at the start, after a
    rejected trial step, after a step that gained less than `ratio` of what its linear model
    predicted (0: never) and every `every` accepted steps, Broyden-updated between; the Jacobian
    it returns is exact (an updated one at the optimum is taken again). `counts` gathers the
    exact Jacobians and the updates."""
    tally = counts if counts is not None else {}

    def wrapped(fun: Any, x0: Any, jac: Any = "2-point", **kw: Any) -> Any:
        if not callable(jac):
            return solver(fun, x0, jac=jac, **kw)
        n = {"since": 0, "run": 0}
        last: list[Any] = []

        def exact(u: NDArray[np.float64]) -> NDArray[np.float64]:
            n["run"] = 0
            tally["exact"] = tally.get("exact", 0) + 1
            return np.asarray(jac(u))

        def fun2(u: NDArray[np.float64]) -> NDArray[np.float64]:
            n["since"] += 1
            return np.asarray(fun(u))

        def jac2(u: NDArray[np.float64]) -> NDArray[np.float64]:
            # more than one evaluation since the last Jacobian: a trial step was rejected
            rejected, n["since"] = n["since"] > 1, 0
            r = np.asarray(fun(u))  # the fit's cache holds it: no run
            du = u - last[0] if last else None
            good = True
            if last and ratio > 0.0 and du is not None:
                r0, J0 = last[1], last[2]
                predicted = float(r0 @ r0 - np.sum((r0 + J0 @ du) ** 2))
                good = predicted > 0.0 and float(r0 @ r0 - r @ r) >= ratio * predicted
            if not last or rejected or not good or n["run"] >= every - 1 or du is None or not float(du @ du) > 0.0:
                J = exact(u)
            else:
                J = last[2] + np.outer((r - last[1]) - last[2] @ du, du) / float(du @ du)
                n["run"] += 1
                tally["updates"] = tally.get("updates", 0) + 1
            last[:] = [u.copy(), r.copy(), J]
            return J

        sol = solver(fun2, x0, jac=jac2, **kw)
        if n["run"] > 0:
            sol.jac = exact(np.asarray(sol.x))
        return sol

    return wrapped


def diagnose_both(case: str, every: int, ratio: float) -> None:
    """The diagnosis of `case` as the package runs it, then with updated Jacobians."""
    import idm_rs

    plain = scipy.optimize.least_squares
    rows = []
    for variant in ("exact", "updated"):
        scipy.optimize.least_squares = plain if variant == "exact" else updating(plain, every, ratio)
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
            diagnose_both(case, a.every, a.ratio)
        return
    plain = scipy.optimize.least_squares
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
            counts: dict[str, int] = {}
            scipy.optimize.least_squares = plain if variant == "exact" else updating(plain, a.every, a.ratio, counts)
            t, e0 = time.perf_counter(), sim.evaluations
            try:
                r = fit(pb.obj, nom.spec, free, max_nfev=a.nfev)
            finally:
                scipy.optimize.least_squares = plain
            done = "every step" if variant == "exact" else f"{counts.get('exact', 0)} / {counts.get('updates', 0)}"
            name = case.rstrip("/").split("/")[-1]
            print(f"| {name} | {pb.obj.n} | {variant} | {r.chi2 / pb.obj.n:.4f} | {r.nfev} | {sim.evaluations - e0} | "
                  f"{time.perf_counter() - t:.1f} | {done} |", flush=True)


if __name__ == "__main__":
    main()
