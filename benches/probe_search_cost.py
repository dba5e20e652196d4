"""Probe: where a population search's seconds go — the engine, or the Python around it?

    python benches/probe_search_cost.py CASE_DIR

Builds the diagnosis's objective on the recording in CASE_DIR as `idm_rs.diagnose` does, runs
the calibration's differential-evolution search (`calibration.search`, over the nominal
subset, first cycle) under cProfile, and prints the models simulated, the seconds per model,
and the seconds spent waiting on the engine's batch (`BatchRun.wait`) against the whole. A
probe, not a test: the search is the package's, unchanged.
"""

from __future__ import annotations

import cProfile
import pstats
import sys
import time

from idm_rs.diagnosis.calibration import search
from idm_rs.diagnosis.candidates import calibration_params, nominal_model
from idm_rs.diagnosis.case_model import CaseSimulator
from idm_rs.diagnosis.fitting import Objective
from idm_rs.diagnosis.noise import estimate_noise
from idm_rs.diagnosis.problem import Problem
from idm_rs.io.recording import load_case


def main(case: str) -> None:
    rec = load_case(case)
    noise = estimate_noise(rec)
    sim = CaseSimulator(rec)
    pb = Problem(rec, noise, sim, Objective(rec, sim, noise.sigma), None)
    nominal = nominal_model(pb)
    free = calibration_params(nominal.params)
    profile = cProfile.Profile()
    t0 = time.perf_counter()
    profile.enable()
    _, _, models = search(pb.obj, nominal.spec, free)
    profile.disable()
    seconds = time.perf_counter() - t0
    stats = pstats.Stats(profile).stats  # type: ignore[attr-defined]
    waiting = sum(v[3] for k, v in stats.items() if k[2] == "<method 'wait' of 'idm_rs._core.BatchRun' objects>")
    print(f"{rec.name}: {len(rec.experiments)} experiments, {len(free)} free parameters")
    print(f"population search: {models} models over the first cycle in {seconds:.1f} s "
          f"({1e3 * seconds / models:.2f} ms per model)")
    print(f"waiting on the engine: {waiting:.1f} s ({100 * waiting / seconds:.0f} %); the rest "
          f"(building the models, the misfit, scipy's bookkeeping): {seconds - waiting:.1f} s")


if __name__ == "__main__":
    if len(sys.argv) != 2:
        raise SystemExit(__doc__)
    main(sys.argv[1])
