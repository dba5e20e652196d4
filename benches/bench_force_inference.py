"""What the force inference sees at a case's calibrated model: the calibration as the diagnosis
runs it, then (1) the inferred force on the main body with a trace of every Levenberg-Marquardt
trial (chi^2, the linearised prediction, the undamped Gauss-Newton step's, the gain ratio, the
damping, the smoothing GCV chose) and (2) the knot derivatives the engine gives (after the
inference's own repair) against central differences of runs at 1e-6, 1e-4 and 1e-2 N: the
three largest columns of each experiment and a median one.

    python benches/bench_discovery_structures.py --jsonl /tmp/none.jsonl --write-only /tmp/cases --only 25
    python benches/bench_force_inference.py /tmp/cases/case025

A column many times its differences has blown up (a tangent pass through a fast slip that
stayed finite); the inference then fails every damped step while its linearisation promises
most of chi^2. Results: benches/RESULTS.md §48.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np

from idm_rs.diagnosis.discovery import infer

sys.path.insert(0, str(Path(__file__).resolve().parent))
from at_screening import at_screening


def _report(s: Any, t0: float) -> None:
    cal, pb, rec = s.cal, s.pb, s.rec
    sigma = pb.sigma
    print(f"calibration: {cal.fit.rms / sigma:.2f} x noise, chi^2 {cal.fit.chi2:.0f} over {cal.fit.n} samples "
          f"({time.perf_counter() - t0:.0f} s)", flush=True)
    trace: list[dict[str, float]] = []
    f = infer.infer_force(rec, cal.fit.spec, sigma, "main", simulator=pb.obj.sim, nuisance=list(cal.at),
                          trace=trace)
    print(f"inferred force on the main body: chi^2 {f.chi2_before:.0f} -> {f.chi2_after:.0f}, {f.dof:.1f} effective "
          f"parameters, smoothing {f.smoothing:g}, {sum(k.size for k in f.knots)} knots, {f.seconds:.0f} s", flush=True)
    print("trial  chi2  trial_chi2  predicted  undamped  rho  mu", flush=True)
    for i, t in enumerate(trace):
        print(f"{i:3d} {t['chi2']:.0f} {t['trial_chi2']:.0f} {t['predicted_chi2']:.0f} {t['undamped_chi2']:.0f} "
              f"{t['rho']:.3g} {t['mu']:.3g}", flush=True)
    for j, A in enumerate(f.jacobians):
        n = np.linalg.norm(A, axis=0)
        print(f"exp {j}: column norms median {np.median(n):.3g}, max {n.max():.3g}, "
              f"{np.mean(n < 1e-3 * n.max()):.0%} under 1e-3 of the max", flush=True)

    # the derivatives at the calibrated model, no force, against differences of runs
    knots = [infer.knot_times(rec, j, infer.FIT_DT) for j in range(len(rec.experiments))]
    prob = infer._ForceFit(rec, cal.fit.spec, sigma, "main", pb.obj.sim, knots, [], 2, None)
    try:
        vals = [np.full(k.size, infer.START_FORCE) for k in knots]
        u = np.zeros(0)
        A, _ = prob.view(prob.evaluate(vals, u, True))
        print("exp knot t[ms] |column| |difference| at 1e-6 / 1e-4 / 1e-2 N", flush=True)
        for j in range(len(A)):
            norms = np.linalg.norm(A[j], axis=0)
            order = np.argsort(norms)
            for k in list(order[-3:]) + [order[len(order) // 2]]:
                diffs = []
                for h in (1e-6, 1e-4, 1e-2):
                    up = [v.copy() for v in vals]
                    dn = [v.copy() for v in vals]
                    up[j][k] += h
                    dn[j][k] -= h
                    rp = prob.residual(prob.evaluate(up, u, False))[0][j]
                    rm = prob.residual(prob.evaluate(dn, u, False))[0][j]
                    diffs.append(float(np.linalg.norm((rp - rm) / (2 * h) / sigma)))
                print(f"{j} {k} {knots[j][k] * 1e3:.2f} {norms[k]:.3g} " + " / ".join(f"{d:.3g}" for d in diffs),
                      flush=True)
    finally:
        prob.pool.shutdown()


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("case", help="a case directory (idm-recording/1)")
    a = ap.parse_args()
    t0 = time.perf_counter()
    at_screening(a.case, "the force inference's report", lambda s: _report(s, t0))


if __name__ == "__main__":
    main()
