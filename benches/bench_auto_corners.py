"""Where ``method="auto"``'s setting comes from: the error of each adaptive candidate against RK4
at dt = 1e-8 s in the four corners of the benchmark grid (m2/m1 in 0.25-2 x V in 40-120 V), where
the dynamics are hardest (a light weight at high voltage slides longest; a heavy one at low
voltage barely moves). Each corner is a 12 x 12 grid; paper case, 10 ms.

    python benches/bench_auto_corners.py [--models lps,dps] [--json PATH]
    python benches/bench_auto_corners.py --summary PATH.json   (the ratios of a finished run)

Prints, per model, corner and candidate: the largest |x1 - x1_RK4| [m], the number of points
beyond 1 nm, the median steps per point and the points per second (2 threads). A fifth corner
is a stiff contact (presliding stiffness up to 1,000x the paper's), where ``auto`` should change
to Rodas4. (Together with the 16 x 16 grid of
``bench_sweep.py``, this is the measurement ``idm_rs.core.methods.AUTO`` follows.)
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import numpy as np

import idm_rs

#: name -> (first axis, its range, log-spaced?, voltage range)
CORNERS = {
    "light weight, high voltage": ("mass_ratio", (0.25, 0.40), False, (105.0, 120.0)),
    "heavy weight, low voltage": ("mass_ratio", (1.8, 2.0), False, (40.0, 55.0)),
    "light weight, low voltage": ("mass_ratio", (0.25, 0.40), False, (40.0, 55.0)),
    "heavy weight, high voltage": ("mass_ratio", (1.8, 2.0), False, (105.0, 120.0)),
    # a stiff contact: the presliding stiffness 10-1,000x the paper's, where the explicit method
    # is held at its stability limit through every sliding phase (the 192-point sweep)
    "stiff contact (fric_alpha 2e9-2e11)": ("fric_alpha", (2e9, 2e11), True, (40.0, 120.0)),
}
#: (method, rtol = atol); None: the method's own setting ("auto": idm_rs.core.methods.AUTO)
CANDIDATES = (("dopri5", 1e-6), ("dopri5", 3e-7), ("dopri5", 1e-7), ("rodas4", 1e-5), ("rodas4", 3e-6),
              ("auto", None))


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--models", default="lps,dps")
    ap.add_argument("--size", type=int, default=12, help="points per corner axis (default 12)")
    ap.add_argument("--corners", default="", help="comma-separated name fragments (default: all)")
    ap.add_argument("--json", metavar="PATH")
    ap.add_argument("--candidates", default="", help="method:tol,... instead of CANDIDATES (e.g. "
                    "'rodas4:3e-5,rodas4:1e-4,auto:')")
    ap.add_argument("--summary", metavar="PATH.json", help="print the ratios of a finished run's JSON and stop")
    a = ap.parse_args(argv)
    if a.summary:
        summary(json.loads(Path(a.summary).read_text()))
        return 0
    p, w = idm_rs.Params(), idm_rs.Triangle(80.0, 0.5e-3, 9.5e-3)
    out = []
    for model in a.models.split(","):
        kw = dict(t_end=10e-3, model=model, n_elements=4, progress=False, threads=2)
        for name, (axis, (a0, a1), log, (v0, v1)) in CORNERS.items():
            if a.corners and not any(c in name for c in a.corners.split(",")):
                continue
            first = np.geomspace(a0, a1, a.size) if log else np.linspace(a0, a1, a.size)
            g = {axis: first, "voltage": np.linspace(v0, v1, a.size)}
            ref = idm_rs.sweep(p, w, g, dt=1e-8, **kw)["final_position"].values
            chosen = CANDIDATES if not a.candidates else tuple(
                (m, float(t) if t else None) for m, t in (c.split(":") for c in a.candidates.split(",")))
            for method, tol in chosen:
                t0 = time.perf_counter()
                ds = idm_rs.sweep(p, w, g, method=method, **(dict(rtol=tol, atol=tol) if tol else {}), **kw)
                wall = time.perf_counter() - t0
                e = np.abs(ds["final_position"].values - ref)
                row = dict(model=model, corner=name, method=method, tol=tol, max_err_m=float(e.max()),
                           points_over_1nm=int((e > 1e-9).sum()), median_steps=float(np.median(ds.steps.values)),
                           wall_s=wall, points_per_s=e.size / wall,
                           statuses=np.bincount(ds.status.values.ravel()).tolist())
                out.append(row)
                print(f"{model} | {name} | {method} {tol if tol else '(own)'}: max |dx1| {e.max():.2e} m, > 1 nm: "
                      f"{row['points_over_1nm']}, median steps {row['median_steps']:.0f}, {row['points_per_s']:.0f} "
                      "points/s", flush=True)
    summary(out)
    if a.json:
        Path(a.json).write_text(json.dumps(out, indent=2) + "\n")
    return 0


def summary(rows: list[dict]) -> None:
    """Per model and corner: auto's points/s against the fastest single method that kept every
    point within 1 nm (the issue's "auto never below 0.9x the best single method")."""
    print("\nauto against the fastest single method within 1 nm (points/s):")
    for key in dict.fromkeys((r["model"], r["corner"]) for r in rows):
        here = [r for r in rows if (r["model"], r["corner"]) == key]
        auto = [r for r in here if r["method"] == "auto"]
        single = [r for r in here if r["method"] != "auto" and r["points_over_1nm"] == 0]
        if not auto or not single:
            continue
        best = max(single, key=lambda r: r["points_per_s"])
        ratio = auto[0]["points_per_s"] / best["points_per_s"]
        print(f"  {key[0]} | {key[1]}: auto {auto[0]['points_per_s']:.0f} against {best['method']} {best['tol']} "
              f"{best['points_per_s']:.0f}: {ratio:.2f}x (auto beyond 1 nm: {auto[0]['points_over_1nm']})")


if __name__ == "__main__":
    raise SystemExit(main())
