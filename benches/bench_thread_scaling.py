"""Thread scaling of the CPU sweep (issue 34, part 4): the same grid (LPS, paper case, 10 ms,
m2/m1 0.25-2 x V 40-120 V, method="auto") at 1..N threads, and the 200 x 200 grid at half and all
of the cores; every run's final positions must be bitwise the first's.

    python benches/bench_thread_scaling.py --threads 1 2 4 8 12 16 --json threads.json

Writes one JSON row per run (points/s of the whole sweep call and of the engine alone)."""

import argparse
import json
import os
import time

import numpy as np

import idm_rs


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--threads", type=int, nargs="+", default=[1, 2])
    ap.add_argument("--side", type=int, default=64, help="grid side of the scaling runs (default 64: 4,096 points)")
    ap.add_argument("--big", type=int, default=200, help="grid side of the all-cores run (0: skip)")
    ap.add_argument("--json", default=None)
    a = ap.parse_args()
    out = {"cpu_count": os.cpu_count(), "simd_level": idm_rs.core.engine.simd_level(), "rows": []}
    w = idm_rs.Triangle()
    idm_rs.sweep(idm_rs.Params(), w, {"voltage": [80.0]}, model="lps", method="auto", progress=False)  # warm-up
    grid = {"mass_ratio": np.linspace(0.25, 2, a.side), "voltage": np.linspace(40, 120, a.side)}
    ref = None
    for threads in a.threads:
        t0 = time.perf_counter()
        ds = idm_rs.sweep(idm_rs.Params(), w, grid, model="lps", method="auto", threads=threads, progress=False,
                          metrics=["final_position"])
        wall = time.perf_counter() - t0
        fp = ds.final_position.values
        ref = fp if ref is None else ref
        row = {"threads": threads, "points": int(fp.size), "wall_s": wall, "points_per_s": fp.size / wall,
               "engine_wall_s": float(ds.attrs["wall_time_s"]), "bitwise_same": bool(np.array_equal(fp, ref)),
               "steps_mean": float(ds.steps.values.mean()), "steps_max": int(ds.steps.values.max())}
        out["rows"].append(row)
        print(json.dumps(row), flush=True)
    if a.big:
        g2 = {"mass_ratio": np.linspace(0.25, 2, a.big), "voltage": np.linspace(40, 120, a.big)}
        for threads in sorted({max(1, (os.cpu_count() or 2) // 2), os.cpu_count() or 1}):
            t0 = time.perf_counter()
            ds = idm_rs.sweep(idm_rs.Params(), w, g2, model="lps", method="auto", threads=threads, progress=False,
                              metrics=["final_position"])
            wall = time.perf_counter() - t0
            row = {"grid": f"{a.big}x{a.big}", "threads": threads, "wall_s": wall, "points_per_s": a.big ** 2 / wall,
                   "engine_wall_s": float(ds.attrs["wall_time_s"])}
            out["rows"].append(row)
            print(json.dumps(row), flush=True)
    if a.json:
        with open(a.json, "w") as f:
            json.dump(out, f, indent=1)


if __name__ == "__main__":
    main()
