"""Where a fit's time goes: for each recording, which experiments' derivatives the engine can
take at the fit step (RK4 at FIT_DT) at the nominal values, and one local fit of the calibrated
subset from there split into its plain evaluations, its sensitivity passes and its difference
columns (seconds and simulated runs).

    python benches/bench_fit_cost.py ../shared/recordings/dev/dev05 ../shared/recordings/dev2/d2_06

An experiment whose derivatives blow up (a fast slip beyond the friction state's RK4 stability
limit at the fit step: the plain run stays bounded, its derivative does not) takes forward
differences on the engine's lanes for the rest of the fit. Results: benches/RESULTS.md §47.
"""

from __future__ import annotations

import argparse
import time
from typing import Any, Callable

import numpy as np

from idm_rs.diagnosis import fitting
from idm_rs.diagnosis.candidates import nominal_model
from idm_rs.diagnosis.case_model import CaseSimulator
from idm_rs.diagnosis.fitting import Objective, fit
from idm_rs.diagnosis.noise import estimate_noise
from idm_rs.diagnosis.problem import Problem, calibration_params
from idm_rs.io.recording import load_case


def _timed(seconds: dict[str, float], key: str, f: Callable[..., Any]) -> Callable[..., Any]:
    def g(*a: Any, **k: Any) -> Any:
        t = time.perf_counter()
        try:
            return f(*a, **k)
        finally:
            seconds[key] += time.perf_counter() - t
    return g


def one(case: str, nfev: int) -> str:
    rec = load_case(case)
    noise = estimate_noise(rec)
    sim = CaseSimulator(rec, threads=1)
    pb = Problem(rec, noise, sim, Objective(rec, sim, noise.sigma), None)
    nom = nominal_model(pb)
    free = calibration_params(nom.params)
    blew: set[int] = set()
    pb.obj.jacobian(nom.spec, free, np.zeros(len(free)), unbounded=blew)
    s = {"plain": 0.0, "sensitivities": 0.0, "differences": 0.0}
    plain, checked, sens, diff = (sim.predict, sim.predict_checked, sim.predict_with_sensitivities,
                                  fitting.difference_columns)
    sim.predict = _timed(s, "plain", plain)  # type: ignore[method-assign]
    sim.predict_checked = _timed(s, "plain", checked)  # type: ignore[method-assign]
    sim.predict_with_sensitivities = _timed(s, "sensitivities", sens)  # type: ignore[method-assign]
    fitting.difference_columns = _timed(s, "differences", diff)  # type: ignore[assignment]
    try:
        t0, e0 = time.perf_counter(), sim.evaluations
        r = fit(pb.obj, nom.spec, free, max_nfev=nfev)
        total, runs = time.perf_counter() - t0, sim.evaluations - e0
    finally:
        sim.predict, sim.predict_checked, sim.predict_with_sensitivities, fitting.difference_columns = (  # type: ignore
            plain, checked, sens, diff)
    s["plain"] -= s["differences"]  # the differences' batches go through `predict` too
    name = case.rstrip("/").split("/")[-1]
    return (f"| {name} | {len(rec.experiments)} | {len(blew)} | {len(free)} | {r.nfev} | {runs} | {total:.1f} | "
            f"{s['plain']:.1f} | {s['sensitivities']:.1f} | {s['differences']:.1f} |")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("cases", nargs="+")
    ap.add_argument("--nfev", type=int, default=12, help="the fit's evaluations (default 12)")
    a = ap.parse_args()
    print("| recording | experiments | by differences at the nominal values | free | evaluations | runs | s | "
          "plain s | sensitivities s | differences s |")
    print("|---|---|---|---|---|---|---|---|---|---|")
    for c in a.cases:
        print(one(c, a.nfev), flush=True)


if __name__ == "__main__":
    main()
