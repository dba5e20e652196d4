"""§24 device run (the GPU machine's 16-core host; the card not used): the LPS `auto`
sweep over the 10^6 grid's ranges with this section's engine, 200 x 200 on 1 and 16 threads,
then the whole 1,000 x 1,000 on 16 threads. Prints one JSON line per run."""
import json
import os
import platform
import resource
import sys
import time

import numpy as np

import idm_rs

p, w = idm_rs.Params(), idm_rs.Triangle(80.0, 0.5e-3, 9.5e-3)
info = {"simd": idm_rs.core.engine.simd_level(), "cpus": os.cpu_count(), "processor": platform.processor()}
print(json.dumps(info), flush=True)
for side, threads in [(int(a.split("x")[0]), int(a.split("x")[1])) for a in sys.argv[1:]]:
    g = {"mass_ratio": np.linspace(0.25, 2.0, side), "voltage": np.linspace(40.0, 120.0, side)}
    t0 = time.perf_counter()
    ds = idm_rs.sweep(p, w, g, method="auto", t_end=10e-3, model="lps", threads=threads, progress=False)
    wall = time.perf_counter() - t0
    print(json.dumps({"side": side, "threads": threads, "wall_s": wall, "points_per_s": side * side / wall,
                      "sweep_wall_s": ds.attrs.get("wall_time_s"), "ok": int((ds.status.values == 1).sum()),
                      "steps_mean": float(ds.steps.mean()), "final_position_sum": float(ds.final_position.sum()),
                      "peak_rss_mib": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024}), flush=True)
