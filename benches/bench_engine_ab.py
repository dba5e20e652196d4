"""The same CLI sweep through two installed copies of the package (two engines), alternated, and
whether every output variable is bitwise equal: how an engine change is measured (a ratio taken
in one session on one machine, benches/RESULTS.md §24).

    python benches/bench_engine_ab.py BEFORE/python AFTER/python [--side 60] [--repeats 2]
        [--method auto] [--model lps] [--out DIR]

BEFORE and AFTER are directories that hold an ``idm_rs`` package with its built ``_core`` (a
snapshot: ``git archive HEAD python | tar -x -C DIR`` and the built ``.so`` copied in). The grid
is SIDE x SIDE points of the 10^6 sweep's ranges (m2/m1 0.25-2 x V 40-120), t_end 10 ms.
"""

from __future__ import annotations

import argparse
import subprocess
import sys
from pathlib import Path

import numpy as np
import xarray as xr


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("before")
    ap.add_argument("after")
    ap.add_argument("--side", type=int, default=60)
    ap.add_argument("--repeats", type=int, default=2)
    ap.add_argument("--method", default="auto")
    ap.add_argument("--model", default="lps")
    ap.add_argument("--out", default=".", help="directory for the two runs' netCDF files")
    a = ap.parse_args(argv)
    engines = {"before": a.before, "after": a.after}
    n = a.side
    for rep in range(a.repeats):
        res = {}
        for name, path in engines.items():
            out = Path(a.out) / f"engine_ab_{name}_{rep}.nc"
            out.unlink(missing_ok=True)
            subprocess.run([sys.executable, "-m", "idm_rs", "sweep", "--model", a.model, "--method", a.method,
                            "--t-end", "10e-3", "--grid", f"mass_ratio=0.25:2:{n}", "--grid", f"voltage=40:120:{n}",
                            "--out", str(out), "--no-progress"],
                           env={"PYTHONPATH": path, "PATH": "/usr/bin:/bin"}, check=True, capture_output=True)
            with xr.open_dataset(out) as f:
                res[name] = ds = f.load()
            print(f"{rep}: {name}: {ds.attrs['wall_time_s']:.2f} s, {n * n / ds.attrs['wall_time_s']:.0f} points/s, "
                  f"steps mean {float(ds['steps'].mean()):.0f}", flush=True)
        b, c = res["before"], res["after"]
        same = all(np.array_equal(b[v].values, c[v].values, equal_nan=True) for v in b.data_vars if v != "reason")
        dx = float(np.abs(b["final_position"] - c["final_position"]).max())
        print(f"{rep}: every output bitwise equal: {same}; max |final position difference| {dx:.3e} m", flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
