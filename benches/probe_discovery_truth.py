"""One discovery-bench device (``bench_discovery_structures.py``'s plan) written again, its true
model (the true parameters and the library term at the true coefficient) scored under the
diagnosis's own objective, and local refits of the calibrated subset with that term from the
truth and from the nominal values: is a miss the search's (the truth leaves noise where the
fits did not) or the library's?

    python benches/probe_discovery_truth.py --seed 1 --id 10 [--dir /tmp/cases] [--nfev 25]

Forms with one library term only (V, x1^2, x1^3, v1, v1|v1|, the weight's dry friction); the
periodic frictions need their phase and are refused.
"""

from __future__ import annotations

import argparse
import math
import sys
import tempfile
import time
from pathlib import Path
from typing import Optional

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))
sys.path.insert(0, str(HERE.parent / "tests"))
from bench_discovery_structures import plan, run_case  # noqa: E402

#: mechanism -> (its field in the simulator's extra, the library term, the coefficient's sign)
TERMS: dict[str, tuple[str, str, float]] = {
    "voltage_force": ("c", "lib_volt", 1.0), "quadratic_spring": ("k2", "lib_x1sq", -1.0),
    "cubic_spring": ("k3", "lib_x1cube", -1.0), "linear_drag": ("c1", "lib_v1", -1.0),
    "quadratic_drag": ("c2", "lib_vv", -1.0), "weight_dry_friction": ("fw", "libw_sgn", -1.0)}


def main(argv: Optional[list[str]] = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--id", type=int, required=True)
    ap.add_argument("--dir", type=Path, help="where the device is written (default: a temporary directory)")
    ap.add_argument("--nfev", type=int, default=25, help="each local refit's evaluations (discovery's: 25)")
    a = ap.parse_args(argv)
    import numpy as np

    import offcatalogue as oc
    from idm_rs.diagnosis.candidates import nominal_model
    from idm_rs.diagnosis.case_model import CaseSimulator, ModelSpec
    from idm_rs.diagnosis.fitting import FreeParam, Objective, fit, set_effect
    from idm_rs.diagnosis.noise import estimate_noise
    from idm_rs.diagnosis.problem import Problem, calibration_params
    from idm_rs.diagnosis.whiteness import whiteness_z
    from idm_rs.io.recording import load_case

    c = next(x for x in plan(1) if x["id"] == a.id)
    if c["mechanism"] not in TERMS:
        ap.error(f"device {a.id} is a {c['mechanism']}: only {', '.join(TERMS)} are scored")
    root = a.dir or Path(tempfile.mkdtemp())
    info = run_case(c, root, a.seed, diagnose=False)
    field, term, sign = TERMS[c["mechanism"]]
    k = sign * float(info["extra"][field])
    rec = load_case(root / f"case{a.id:03d}")
    noise = estimate_noise(rec)
    sim = CaseSimulator(rec)
    obj = Objective(rec, sim, noise.sigma)
    nom = nominal_model(Problem(rec, noise, sim, obj, None))
    free = calibration_params(nom.params)
    true = {f.name: float(oc.DEV10_PARAMS.get(f.name, f.x0)) for f in free}
    print(f"device {a.id} (seed {a.seed}): {c['mechanism']} on the {c['structure']}, {term} = {k:.4g}; "
          f"mis-set {info['misset']}; noise {noise.sigma:.3e} m")

    def scored(label: str, spec: ModelSpec) -> None:
        res, _ = obj.profiled(obj.predict([spec])[0])
        n = sum(r.size for r in res)
        chi2 = float(sum(np.sum(r * r) for r in res)) / noise.sigma**2
        print(f"  {label:34s} RMS {math.sqrt(chi2 / n):7.3f} x noise, whiteness z {whiteness_z(res, obj):6.1f}")

    truth = ModelSpec(nom.structure, {**nom.params, **true}, {term: k})
    scored("the nominal model", nom.spec)
    scored("the true parameters, no term", ModelSpec(nom.structure, {**nom.params, **true}, {}))
    scored("the truth", truth)
    lib = FreeParam(term, k, k - 20.0 * abs(k), k + 20.0 * abs(k), 0.1 * abs(k), set_effect(term))
    for label, start in (("from the truth", true), ("from the nominal values", None)):
        t0 = time.perf_counter()
        r = fit(obj, nom.spec, [f.at(start[f.name]) if start else f for f in free] + [lib], max_nfev=a.nfev)
        moved = ", ".join(f"{f.name} {100 * (r.values[f.name] / true[f.name] - 1):+.0f} %" for f in free)
        print(f"  refit {label:28s} RMS {r.rms / noise.sigma:7.3f} x noise, whiteness z "
              f"{whiteness_z(r.residuals, obj):6.1f}, {r.nfev} evaluations, {time.perf_counter() - t0:.0f} s; "
              f"{term} {100 * (r.values[term] / k - 1):+.0f} %; against the truth: {moved}", flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
