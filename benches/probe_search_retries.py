"""Probe: what the calibration's population search sees without retries, and what retries cost.

    python benches/probe_search_retries.py CASE_DIR [--members 40] [--repeats 2]

The population searches and the one-dimensional scans (`diagnosis.calibration`) run their
members with `retries=0`: a member that diverges at the fit step scores as diverged. On a device
whose runs need a finer step near the nominal values the searches then see only the members whose
slips are slow enough for the fit step. This draws `--members` points uniformly over the
calibration's box (`problem.calibration_params`, fixed seed), runs the first cycle of every
experiment without and with the fits' retries (dt/2, dt/4) in one batch each, alternated
`--repeats` times, and prints the wall seconds and how many members came back finite in every
experiment. A probe, not a test: the package's simulator, unchanged (benches/RESULTS.md §69).
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from idm_rs.core.batch import Structure
from idm_rs.diagnosis.case_model import CaseSimulator, ModelSpec
from idm_rs.diagnosis.fitting import apply
from idm_rs.diagnosis.problem import calibration_params
from idm_rs.io.recording import load_case


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("case")
    ap.add_argument("--members", type=int, default=40)
    ap.add_argument("--repeats", type=int, default=2)
    a = ap.parse_args()
    rec = load_case(a.case)
    nom = rec.nominal
    p0 = nom.params.to_dict(resolved=False)
    base = ModelSpec(Structure(nom.model, nom.n_elements, nom.piezo_hysteresis), p0, {})
    free = calibration_params(p0)
    lo = np.array([f.u_bounds()[0] for f in free])
    hi = np.array([f.u_bounds()[1] for f in free])
    u = lo + (hi - lo) * np.random.default_rng(0).random((a.members, len(free)))
    specs = [apply(base, free, x) for x in u]
    sim = CaseSimulator(rec)
    for _ in range(a.repeats):
        for retries in (0, 2):
            t = time.perf_counter()
            out = sim.predict(specs, 1, retries=retries)
            wall = time.perf_counter() - t
            finite = sum(all(np.all(np.isfinite(o)) for o in m) for m in out)
            print(f"retries {retries}: {wall:.2f} s, {finite} of {len(specs)} members finite in every experiment")


if __name__ == "__main__":
    main()
