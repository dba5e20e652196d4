"""Cost of parameter sensitivities from the engine (issue 17): a run with ``n`` sensitivities
against the plain run, in the same process and run.

Cases: the paper device (Triangle(80 V, 0.5 ms, 9.5 ms)), 2 ms at RK4 dt = 1e-8 s (2·10^5
steps), LPS and DPS with 4 elements; n = 1, 2, 4, 8 names by default, up to 12 with ``--counts``
(Table 1 parameters the diagnosis fits; a pass carries up to 8 names, on a tangent as wide as
it needs, so the cost steps at 1, 2, 4, 8 and 8 + 1, 2, 4).
Each call is timed end to end (``simulate(..., sensitivities=names)`` runs the plain run and
then the derivative pass), best of ``--repeats``, after one warm-up. Printed: a markdown table of
case, plain [ms], with n sensitivities [ms], and the ratio in plain runs, against the issue's
goal of at most 1 + n. Run on a quiet machine::

    python benches/bench_sensitivities.py [--repeats 5] [--counts 1 2 3 4 5 8 9 10 11 12]
"""

from __future__ import annotations

import argparse
import os
import platform
import time

import idm_rs

NAMES = ["mu_k", "m2", "fric_alpha", "sigma1", "mu_s", "d33", "hyst_alpha", "sigma2", "m1", "fric_beta",
         "stribeck_velocity", "rayleigh_alpha"]
WAVE = idm_rs.Triangle(80.0, 0.5e-3, 9.5e-3)


def best(repeats: int, **kw) -> float:
    idm_rs.simulate(idm_rs.Params(), WAVE, **{**kw, "t_end": 0.2e-3})  # warm-up
    times = []
    for _ in range(repeats):
        t = time.perf_counter()
        idm_rs.simulate(idm_rs.Params(), WAVE, **kw)
        times.append(time.perf_counter() - t)
    return min(times)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--counts", type=int, nargs="+", default=[1, 2, 4, 8],
                    help=f"numbers of names (1 to {len(NAMES)})")
    args = ap.parse_args()
    print(f"machine: {os.cpu_count()} CPUs, {platform.processor() or platform.machine()}, "
          f"load {os.getloadavg()[0]:.2f}; idm_rs {idm_rs.__version__}")
    print("| model | plain [ms] | n | with sensitivities [ms] | in plain runs | goal (1 + n) |")
    print("|---|---:|---:|---:|---:|---:|")
    for model in ("lps", "dps"):
        run = dict(t_end=2e-3, dt=1e-8, model=model, n_elements=4, save_every=100)
        plain = best(args.repeats, **run)
        for n in args.counts:
            with_s = best(args.repeats, sensitivities=NAMES[:n], **run)
            label = "LPS" if model == "lps" else "DPS4"
            print(f"| {label} | {plain * 1e3:.1f} | {n} | {with_s * 1e3:.1f} | {with_s / plain:.2f} | {1 + n} |",
                  flush=True)


if __name__ == "__main__":
    main()
