"""A case's inferred force on the main body at its calibrated model, with the inference given
`--iterations` accepted Levenberg-Marquardt steps each, and the regression's form on each force
(plain, and with the calibrated parameters' directions projected out): what discovery would find
if it started from the calibrated model.

    python benches/bench_discovery_structures.py --seed 1 --jsonl /tmp/none.jsonl --write-only /tmp/cases --only 18
    python benches/probe_inference_regression.py /tmp/cases/case018 [--iterations 8 24] [--discover]

With ``--discover``, then discovery itself from each centre of ``--at`` (the calibrated model is
not a path discovery takes after ``not_converged``): its verdict, form, RMS and reason.

Results: benches/RESULTS.md §65 (a linear drag on the DPS 4: v1|v1| at cross-validated error
0.009 from the calibrated model, refitted 4.32 x noise: discovery from there finds nothing).
"""

from __future__ import annotations

import argparse
import sys
import time
from dataclasses import replace
from pathlib import Path
from typing import Any

from idm_rs.diagnosis.discovery import infer
from idm_rs.diagnosis.discovery.regress import find_terms

sys.path.insert(0, str(Path(__file__).resolve().parent))
from at_screening import at_screening


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("case", help="a case directory (idm-recording/1)")
    ap.add_argument("--iterations", type=int, nargs="+", default=[8, 24])
    ap.add_argument("--discover", action="store_true", help="then discovery from each centre of --at")
    ap.add_argument("--at", nargs="+", default=["calibrated"], choices=["calibrated", "nominal"],
                    help="the inference's centre: the calibrated model, or the nominal values as given (the "
                         "path discovery takes first after not_converged)")
    a = ap.parse_args()
    def report(s: Any) -> None:
        cal, pb, rec = s.cal, s.pb, s.rec
        sigma = pb.sigma
        print(f"calibration {cal.fit.rms / sigma:.2f} x noise, chi^2 {cal.fit.chi2:.0f}", flush=True)
        for at in a.at:
            spec, free = (cal.fit.spec, list(cal.at)) if at == "calibrated" else (s.nominal.spec, list(cal.free))
            for it in a.iterations:
                t0 = time.perf_counter()
                f = infer.infer_force(rec, spec, sigma, "main", simulator=pb.obj.sim, nuisance=free, iterations=it)
                print(f"at the {at} model, {it} accepted steps at most: chi^2 {f.chi2_before:.0f} -> "
                      f"{f.chi2_after:.0f}, {f.dof:.1f} effective parameters, {time.perf_counter() - t0:.0f} s; "
                      f"parameters {', '.join(f'{k} {v:.4g}' for k, v in f.parameters.items())}", flush=True)
                views = [("plain", f, False), ("projected", f, True),
                         ("with the parameters' moves", replace(f, with_nuisance=True), False)]
                for name, view, project in views:
                    form = find_terms(view, project=project)
                    terms = ", ".join(f"{t.symbol} {form.coefficients[t.param]:.4g}" for t in form.terms)
                    print(f"  {name}: {terms or '(none)'}; cross-validated error "
                          f"{form.cv_error:.3f}, by size {[round(x, 3) for x in form.cv_by_size]}", flush=True)
                    for chosen, other, cos in form.look_alikes:
                        print(f"    look-alike: {other} for {chosen}, |cos| {cos:.4f}", flush=True)
        if a.discover:
            from idm_rs.diagnosis.discovery import discover

            ho_cal = s.heldout.rms(cal.fit.spec, cal.at)
            for at in a.at:
                # the paths as beyond_catalogue.discovery_paths makes them
                spec, free = (cal.fit.spec, list(cal.at)) if at == "calibrated" else (s.nominal.spec, list(cal.free))
                t0 = time.perf_counter()
                found = discover(rec, spec, free, pb.obj, s.heldout, ho_cal, nominal=s.nominal.spec, progress=None)
                terms = ", ".join(t.symbol for t in found.form.terms) if found.form is not None else "(none)"
                print(f"discovery from the {at} model: discovered {found.discovered}, {terms}, "
                      f"{found.rms_after / sigma:.3f} x noise, {time.perf_counter() - t0:.0f} s; {found.reason}",
                      flush=True)

    at_screening(a.case, "the inference and regression probe", report)


if __name__ == "__main__":
    main()
