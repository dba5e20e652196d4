"""What one thread costs per method and instruction set, and how `auto` scales with threads
(issue 34, part 4): the LPS and DPS n = 4 paper device, 10 ms, m2/m1 0.25-2 x V 40-120 V;
auto and dopri5 on a side x side grid, rodas4 and RK4 (dt = 5e-8 s) on 8 x 8; one thread, each
instruction set the processor has, two repeats (a shared host shows its noise there); then
`auto` on a scale x scale grid at each thread count. One JSON line per run on stdout.

    python benches/bench_per_thread.py --side 20 --threads 1 2 4 8 16 --scale 48

Run on two machines and compared by ratio: a machine whose threads are slower on every method
alike (the single-trajectory Rodas4 path included) is slower, not the vector lanes on it."""

import argparse
import json
import os
import platform
import time

import numpy as np

import idm_rs


def grid(side: int) -> dict:
    return {"mass_ratio": np.linspace(0.25, 2, side), "voltage": np.linspace(40, 120, side)}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--side", type=int, default=20, help="grid side of the auto and dopri5 runs (default 20)")
    ap.add_argument("--threads", type=int, nargs="+", default=[1, 2])
    ap.add_argument("--scale", type=int, default=48, help="grid side of the thread-scaling runs (default 48)")
    ap.add_argument("--repeats", type=int, default=2)
    a = ap.parse_args()
    w = idm_rs.Triangle()
    idm_rs.sweep(idm_rs.Params(), w, {"voltage": [80.0]}, model="lps", method="auto", progress=False)  # warm-up
    host = {"host": platform.node(), "cpus": os.cpu_count(), "level": idm_rs.core.engine.simd_level()}
    print(json.dumps(host), flush=True)
    levels = ["scalar", "avx2"] + (["avx512"] if "avx512f" in open("/proc/cpuinfo").read() else [])
    default = idm_rs.core.engine.simd_level()
    for model in ["lps", "dps"]:
        for level in levels:
            idm_rs.core.engine.set_simd_level(level)
            for method, kw, g in [("auto", {}, grid(a.side)), ("dopri5", {}, grid(a.side)),
                                  ("rodas4", {}, grid(8)), ("rk4", {"dt": 5e-8}, grid(8))]:
                kws = dict(kw, n_elements=4) if model == "dps" else dict(kw)
                for rep in range(a.repeats):
                    t0 = time.perf_counter()
                    ds = idm_rs.sweep(idm_rs.Params(), w, g, model=model, method=method, threads=1, progress=False,
                                      metrics=["final_position"], **kws)
                    wall = time.perf_counter() - t0
                    n = ds.final_position.size
                    print(json.dumps({"model": model, "level": level, "method": method, "rep": rep, "points": int(n),
                                      "points_per_s": n / wall, "steps_mean": float(ds.steps.values.mean()),
                                      "ns_per_step": wall / float(ds.steps.values.sum()) * 1e9,
                                      "fp_sum": float(np.nansum(ds.final_position.values))}), flush=True)
    idm_rs.core.engine.set_simd_level(default)
    for th in a.threads:
        t0 = time.perf_counter()
        ds = idm_rs.sweep(idm_rs.Params(), w, grid(a.scale), model="lps", method="auto", threads=th, progress=False,
                          metrics=["final_position"])
        wall = time.perf_counter() - t0
        print(json.dumps({"scaling": True, "threads": th, "points": int(ds.final_position.size),
                          "points_per_s": ds.final_position.size / wall}), flush=True)


if __name__ == "__main__":
    main()
