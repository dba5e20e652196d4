"""One launch of each kernel benches/bench_gpu.py measures, for Nsight Compute (occupancy, pipe
use, stalls): LPS and DPS (n = 4) RK4 (dt = 5e-8 s, 1 ms) and Dormand-Prince (auto's
tolerances, 10 ms) on SIDE x SIDE points of the bench's grid (default 128; the RESULTS table
used 512: enough blocks to fill the card).

    SIDE=512 ncu --clock-control none -k regex:idm_ --section SpeedOfLight --section Occupancy \\
        --section LaunchStats --section ComputeWorkloadAnalysis --section WarpStateStats \\
        --metrics sm__pipe_fp64_cycles_active.avg.pct_of_peak_sustained_active \\
        --csv --page details python benches/ncu_probe.py > ncu.csv
"""

import os

import numpy as np

import idm_rs
from idm_rs import methods
from idm_rs.core import engine
from idm_rs.core.batch import Structure, param_row
from idm_rs.gpu import launch_cuda, pack, wave_columns

P = idm_rs.Params()
side = int(os.environ.get("SIDE", "128"))
m = np.linspace(0.25, 2.0, side)
rows = np.array([param_row(P.replace(m2=float(x) * P.m1)) for x in m])
idx = np.repeat(np.arange(side), side)
amp = np.tile(np.linspace(40, 120, side), side)
_, rtol, atol = methods.resolve("auto", 0.0, 0.0)
wave = wave_columns("triangle", dict(amplitude=amp, rise=0.5e-3, fall=9.5e-3, delay=0.0))
for model, nodes in (("lps", 2), ("dps", 5)):
    st = Structure(model, nodes - 1 if model == "dps" else 1, True)
    cfg = st.config(method="rk4", dt=5e-8)
    for method, t_end in (("rk4", 1e-3), ("dopri5", 10e-3)):
        kw = dict(method="dopri5", rtol=rtol, atol=atol, first_step=1e-8) if method == "dopri5" else {}
        b = pack(cfg, rows, np.zeros((rows.shape[0], len(engine.effect_names()))), idx, wave, t_end, 5e-8, **kw)
        h = launch_cuda(b)
        r = h.result()
        print(model, method, b.points, "points", round(h.kernel_s, 4), "s", "ok", int((r["status"] == 1).sum()),
              flush=True)
