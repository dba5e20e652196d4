"""GPU sweep throughput: idm-rs's CUDA kernels (one thread per point: RK4 at a fixed step, and
Dormand-Prince as ``method="auto"`` runs it there) on the 1,000 x 1,000 grid (m2/m1 0.25-2 x
V 40-120 V, LPS paper case, 10 ms), each with points/s, steps per point, the points rerun on
the CPU, and the error against idm-rs RK4 at dt = 1e-8 s on a sample of points. (The issue's
JAX vmap and diffrax comparisons are not in it yet.)

    python benches/bench_gpu.py [--size 1000] [--dt 5e-8] [--methods rk4,auto] [--sample 256] [--json PATH]
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
    from idm_rs.batch import Point, Structure, run

    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--size", type=int, default=1000)
    ap.add_argument("--dt", type=float, default=5e-8, help="RK4 step [s]")
    ap.add_argument("--methods", default="rk4,auto", help="comma-separated: rk4, dopri5, auto")
    ap.add_argument("--model", default="lps", choices=("lps", "dps"))
    ap.add_argument("--backend", default="cuda", choices=("cuda", "kernel-cpu"))
    ap.add_argument("--sample", type=int, default=256, help="points checked against RK4 dt = 1e-8")
    ap.add_argument("--json", metavar="PATH")
    a = ap.parse_args(argv)
    p, w = idm_rs.Params(), idm_rs.Triangle(80.0, 0.5e-3, 9.5e-3)
    g = {"mass_ratio": np.linspace(0.25, 2.0, a.size), "voltage": np.linspace(40.0, 120.0, a.size)}
    kw = dict(t_end=10e-3, model=a.model, n_elements=4, progress=False)
    n = a.size * a.size
    rng = np.random.default_rng(0)
    flat = rng.choice(n, size=min(a.sample, n), replace=False)
    i, j = np.unravel_index(flat, (a.size, a.size))
    # the reference on the sample: the CPU engine's RK4 at dt = 1e-8 s
    m1 = p.m1
    pts = [Point(p.replace(m2=float(g["mass_ratio"][ii]) * m1),
                 waveform=idm_rs.Triangle(float(g["voltage"][jj]), 0.5e-3, 9.5e-3)) for ii, jj in zip(i, j)]
    st = Structure(a.model, 4 if a.model == "dps" else 1, True)
    ref = run(pts, st, t_end=10e-3, method="rk4", dt=1e-8)["final_position"]
    rows = []
    for method in a.methods.split(","):
        step = dict(dt=a.dt) if method == "rk4" else {}
        # warm-up: compiles the kernel (NVRTC) once
        idm_rs.sweep(p, w, {"voltage": [80.0]}, backend=a.backend, method=method, **step, **kw)
        t0 = time.perf_counter()
        ds = idm_rs.sweep(p, w, g, backend=a.backend, method=method, block_size=1 << 20, **step, **kw)
        wall = time.perf_counter() - t0
        err = np.abs(ds["final_position"].values[i, j] - ref)
        rerun = int(np.count_nonzero(np.char.startswith(ds["reason"].values.ravel().astype(str), "failed on the kernel")))
        rows.append(dict(backend=a.backend, method=method, model=a.model, points=n, dt=a.dt if method == "rk4" else None,
                         rtol=ds.attrs["rtol"], wall_s=wall, points_per_s=n / wall,
                         steps_per_point=float(ds["steps"].values.mean()), rerun_on_cpu=rerun,
                         max_err_m_sampled=float(err.max()), beyond_1nm=int((err > 1e-9).sum()), sample=int(flat.size),
                         statuses=np.bincount(ds.status.values.ravel(), minlength=5).tolist()))
        print(json.dumps(rows[-1]), flush=True)
    if a.json:
        Path(a.json).write_text(json.dumps(rows, indent=2) + "\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
