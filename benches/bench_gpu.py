"""GPU sweep throughput: idm-rs's CUDA kernel (RK4, one thread per point) on the 1,000 x 1,000
grid (m2/m1 0.25-2 x V 40-120 V, LPS paper case, 10 ms), with the error against idm-rs RK4 at
dt = 1e-8 s on a sample of points. (The issue's JAX vmap and diffrax comparisons and the
adaptive kernel are not in it yet.)

    python benches/bench_gpu.py [--size 1000] [--dt 5e-8] [--sample 256] [--json PATH]
    python benches/bench_gpu.py --backend kernel-cpu --size 8      # the launch path, on the CPU

Runs where CuPy finds a GPU; ``--backend kernel-cpu`` runs the same kernel source compiled for
the CPU (to check the script and the launch code without a GPU; slow). Not yet run on a GPU:
this project's sessions so far had none (benches/RESULTS.md says so).
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import numpy as np

import idm_rs


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--size", type=int, default=1000)
    ap.add_argument("--dt", type=float, default=5e-8)
    ap.add_argument("--model", default="lps", choices=("lps", "dps"))
    ap.add_argument("--backend", default="cuda", choices=("cuda", "kernel-cpu"))
    ap.add_argument("--sample", type=int, default=256, help="points checked against RK4 dt = 1e-8")
    ap.add_argument("--json", metavar="PATH")
    a = ap.parse_args(argv)
    p, w = idm_rs.Params(), idm_rs.Triangle(80.0, 0.5e-3, 9.5e-3)
    g = {"mass_ratio": np.linspace(0.25, 2.0, a.size), "voltage": np.linspace(40.0, 120.0, a.size)}
    kw = dict(t_end=10e-3, model=a.model, n_elements=4, progress=False)
    # warm-up: compiles the kernel (NVRTC) once
    idm_rs.sweep(p, w, {"voltage": [80.0]}, dt=a.dt, backend=a.backend, **kw)
    t0 = time.perf_counter()
    ds = idm_rs.sweep(p, w, g, dt=a.dt, backend=a.backend, block_size=1 << 20, **kw)
    wall = time.perf_counter() - t0
    n = a.size * a.size
    rng = np.random.default_rng(0)
    flat = rng.choice(n, size=min(a.sample, n), replace=False)
    i, j = np.unravel_index(flat, (a.size, a.size))
    worst = 0.0
    for ii, jj in zip(i, j):
        ref = idm_rs.sweep(p, w, {"mass_ratio": [g["mass_ratio"][ii]], "voltage": [g["voltage"][jj]]}, dt=1e-8,
                           **kw)["final_position"].values.ravel()[0]
        worst = max(worst, abs(float(ds["final_position"].values[ii, jj]) - ref))
    out = dict(backend=a.backend, model=a.model, points=n, dt=a.dt, wall_s=wall, points_per_s=n / wall,
               max_err_m_sampled=worst, sample=int(flat.size), statuses=np.bincount(ds.status.values.ravel()).tolist())
    print(json.dumps(out, indent=2))
    if a.json:
        Path(a.json).write_text(json.dumps(out, indent=2) + "\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
