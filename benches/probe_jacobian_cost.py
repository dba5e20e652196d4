"""Probe: what one fit iteration costs the engine on a recording: one model at its nominal
values, the plain run of every experiment, and the derivative request for k names with the run
and with the readings given (the derivative passes alone, as a fit's Jacobian asks where its
last evaluation ran). Best of 7, milliseconds.

    python benches/probe_jacobian_cost.py CASE_DIR [--threads N]

Results: benches/RESULTS.md §58.
"""

from __future__ import annotations

import argparse
import time
from functools import partial
from typing import Any, Callable

from idm_rs.core.batch import Structure
from idm_rs.diagnosis.case_model import CaseSimulator, ModelSpec
from idm_rs.io.recording import load_case

NAMES = ("m1", "m2", "d33", "mu_k", "mu_s", "sigma2", "fric_alpha", "sigma1", "rayleigh_alpha", "rayleigh_beta",
         "pe_youngs", "fric_beta")


def best(f: Callable[[], Any], n: int = 7) -> float:
    out = float("inf")
    for _ in range(n):
        t = time.perf_counter()
        f()
        out = min(out, time.perf_counter() - t)
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("case")
    ap.add_argument("--threads", type=int)
    a = ap.parse_args()
    rec = load_case(a.case)
    sim = CaseSimulator(rec, threads=a.threads)
    nom = rec.nominal
    spec = ModelSpec(Structure(nom.model, nom.n_elements, nom.piezo_hysteresis), nom.params.to_dict(resolved=False),
                     {})
    at = sim.predict([spec])
    plain = best(lambda: sim.predict([spec]))
    print(f"{a.case}: plain run {plain * 1e3:.0f} ms")
    for k in (1, 4, 7, 12):
        full = best(partial(sim.predict_with_sensitivities, [spec], list(NAMES[:k])))
        alone = best(partial(sim.predict_with_sensitivities, [spec], list(NAMES[:k]), readings=at))
        print(f"  {k:2d} names: derivatives with the run {full * 1e3:.0f} ms, alone {alone * 1e3:.0f} ms; "
              f"a fit iteration (plain + Jacobian) {(plain + full) * 1e3:.0f} -> {(plain + alone) * 1e3:.0f} ms")


if __name__ == "__main__":
    main()
