"""Step cost of one simulation: idm-rs against a careful numba RK4 of the same model.

Runs the paper case (triangle 0 -> 80 V in 0.5 ms, back to 0 V at 10 ms; 10 ms from rest at
dt = 1e-8 s, i.e. 1e6 RK4 steps) for the LPS and the DPS with 4 elements, in one process on
one thread, and prints per model: the cost per step of each implementation [ns/step], their
ratio, and |Δx1(10 ms)| [m]. The two must agree to 1e-12 m (asserted), so that the timing
compares the same computation.

Each timing is the best of ``--repeats`` end-to-end calls, the two implementations alternating
call by call (the setup, under 0.1 % of a call, is included for both): ``idm_rs.simulate(...)`` and
``numba_baseline.simulate_x1(...)``.
The numba kernel is compiled (or loaded from its cache) and idm-rs called once before timing.

    python benches/bench_step_cost.py [--repeats 5] [--json PATH]
"""

from __future__ import annotations

import os

# One thread for everything, set before numba/numpy load their thread pools: the benchmark
# measures the serial cost of a single simulation.
for _var in ("NUMBA_NUM_THREADS", "RAYON_NUM_THREADS", "OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import argparse
import json
import platform
import sys
import time
from pathlib import Path

import numba
import numpy as np

import idm_rs

sys.path.insert(0, str(Path(__file__).resolve().parent))
import numba_baseline

T_END = 10e-3  # s
DT = 1e-8  # s
STEPS = int(round(T_END / DT))
N_ELEMENTS = 4
TOLERANCE = 1e-12  # m, |x1(idm-rs) - x1(numba)| allowed
#: MODEL.md's reference values for x1(10 ms) at dt = 1e-8 s [m], for the printout
EXPECTED = {"lps": 1.678e-6, "dps": 1.711e-6}
CASES = (("LPS", "lps"), (f"DPS{N_ELEMENTS}", "dps"))


def best_of_interleaved(fa, fb, repeats: int):
    """Time ``repeats`` calls of each of ``fa()`` and ``fb()``, alternating a, b, a, b, ..., so
    that load from other processes falls on both alike. Returns, for a then b,
    (best wall time [s], last result, all times [s])."""
    times = ([], [])
    results = [None, None]
    for _ in range(repeats):
        for i, fn in enumerate((fa, fb)):
            t0 = time.perf_counter()
            results[i] = fn()
            times[i].append(time.perf_counter() - t0)
    return [(min(times[i]), results[i], times[i]) for i in (0, 1)]


def run_idm_rs(model: str) -> float:
    """x1(10 ms) [m] from idm-rs for the paper case."""
    r = idm_rs.simulate(
        idm_rs.Params(),
        idm_rs.Triangle(80.0, 0.5e-3, 9.5e-3),
        t_end=T_END,
        dt=DT,
        model=model,
        n_elements=N_ELEMENTS,
        save_every=10**6,
    )
    return r.final_position


def run_numba(params: dict, model: str) -> float:
    """x1(10 ms) [m] from the numba baseline for the paper case."""
    return numba_baseline.simulate_x1(params, model, N_ELEMENTS, T_END, DT)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--repeats", type=int, default=5, help="timed calls per implementation and model (best is kept)")
    ap.add_argument("--json", metavar="PATH", help="also write the numbers to this JSON file")
    args = ap.parse_args(argv)

    params = idm_rs.Params().to_dict()  # Table 1, normal_force filled in (6.90624 N)

    # Warm-up: JIT-compile (or load the cached) numba kernel, and touch idm-rs once, so that
    # neither compilation nor first-call effects land in the timings.
    numba_baseline.simulate_x1(params, "lps", N_ELEMENTS, 1e-6, DT)
    numba_baseline.simulate_x1(params, "dps", N_ELEMENTS, 1e-6, DT)

    rows = []
    for label, model in CASES:
        run_idm_rs(model)
        (t_rs, x_rs, all_rs), (t_nb, x_nb, all_nb) = best_of_interleaved(
            lambda model=model: run_idm_rs(model), lambda model=model: run_numba(params, model), args.repeats
        )
        rows.append(
            {
                "model": label,
                "steps": STEPS,
                "idm_rs_ns_per_step": t_rs / STEPS * 1e9,
                "numba_ns_per_step": t_nb / STEPS * 1e9,
                "ratio_idm_rs_over_numba": t_rs / t_nb,
                "x1_idm_rs_m": x_rs,
                "x1_numba_m": x_nb,
                "x1_abs_diff_m": abs(x_rs - x_nb),
                "x1_expected_m": EXPECTED[model],
                "idm_rs_times_s": all_rs,
                "numba_times_s": all_nb,
            }
        )

    print(f"Paper case, {STEPS:.0e} RK4 steps of {DT:g} s, one thread, best of {args.repeats}")
    head = f"{'model':<6} {'idm-rs ns/step':>15} {'numba ns/step':>14} {'idm-rs/numba':>13} {'|dx1| [m]':>11}"
    print(head)
    print("-" * len(head))
    for r in rows:
        print(
            f"{r['model']:<6} {r['idm_rs_ns_per_step']:>15.1f} {r['numba_ns_per_step']:>14.1f} "
            f"{r['ratio_idm_rs_over_numba']:>13.3f} {r['x1_abs_diff_m']:>11.2e}"
        )
    print()
    for r in rows:
        print(
            f"{r['model']:<6} x1(10 ms): idm-rs {r['x1_idm_rs_m']:.10e} m, numba {r['x1_numba_m']:.10e} m "
            f"(MODEL.md: about {r['x1_expected_m']:.3e} m)"
        )

    if args.json:
        out = {
            "benchmark": "step_cost",
            "case": {"waveform": "Triangle(80.0, 0.5e-3, 9.5e-3)", "t_end_s": T_END, "dt_s": DT,
                     "n_elements": N_ELEMENTS, "repeats": args.repeats, "threads": 1},
            "environment": {"python": platform.python_version(), "numpy": np.__version__,
                            "numba": numba.__version__, "idm_rs": getattr(idm_rs, "__version__", "?"),
                            "machine": platform.machine(), "processor": platform.processor(),
                            "platform": platform.platform()},
            "results": rows,
        }
        Path(args.json).write_text(json.dumps(out, indent=2) + "\n")
        print(f"\nwrote {args.json}")

    # The timing only means something if both compute the same trajectory.
    for r in rows:
        assert r["x1_abs_diff_m"] < TOLERANCE, (
            f"{r['model']}: idm-rs and numba disagree by {r['x1_abs_diff_m']:.3e} m (> {TOLERANCE:g} m)"
        )
    return 0


if __name__ == "__main__":
    sys.exit(main())
