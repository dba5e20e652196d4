"""Probe: where a diagnosis's fits go, by call site, and what each bought.

    python benches/probe_fit_sites.py CASE_DIR [--jsonl OUT]

Wraps the diagnosis's `fit` (in every module that imported it), runs `idm_rs.diagnose` on the
recording in CASE_DIR, and prints per call site (the chain of diagnosis functions that called
it, and the stage's open parts): the fits, their seconds, the evaluations used against the
budget, how many stopped on the budget, and what the last half of each budget-stopped fit's
evaluations took off chi^2 (a fit that moves chi^2 by less than the noise in its last
iterations bought nothing with them). With --jsonl, every fit as one line, written as it finishes
(with the engine's seconds in it, the derivative requests' share, and the points that finished
only at a finer step than the fit step, `retried`, or not at all, `diverged`), and the diagnosis
as the last line. At the end it prints the engine's share of the whole: the batches' wall and
process-CPU seconds by kind (plain runs, derivative passes), so the cores' use shows as CPU over
wall, and how often the engine's derivatives could be used (`fitting.usable_derivative`: usable,
not finite, finite but blown up). A probe, not a test: the wrapped diagnosis is the package's,
unchanged.
"""

from __future__ import annotations

import argparse
import collections
import importlib
import json
import math
import pkgutil
import time
import traceback
from typing import Any

import numpy as np

import idm_rs
import idm_rs.diagnosis as diagnosis
from idm_rs.diagnosis import case_model, fitting, progress


def _site() -> str:
    """The diagnosis functions on the stack (outermost first), without the probe and `fit`."""
    names = [f"{f.filename.rsplit('/', 1)[-1][:-3]}.{f.name}" for f in traceback.extract_stack()
             if "/idm_rs/diagnosis/" in f.filename]
    keep = [n for n in names if not n.startswith(("diagnose.diagnose", "fitting.fit"))]
    return " > ".join(keep[-4:])


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("case")
    ap.add_argument("--jsonl")
    a = ap.parse_args()
    modules = [importlib.import_module(m.name) for m in pkgutil.walk_packages(diagnosis.__path__, "idm_rs.diagnosis.")]
    plain_fit = fitting.fit
    t0 = time.perf_counter()
    # every fit as it finishes, so a long case can be read while it runs
    sink = open(a.jsonl, "w") if a.jsonl else None
    rows: list[dict[str, Any]] = []
    # the engine's batches inside the fit now running: seconds, points, the derivative passes'
    # seconds, and points that finished only at a finer step than the fit step (retried)
    engine: list[dict[str, float]] = []
    plain_run = case_model.run_batch
    # every batch by kind: [calls, wall s, process-CPU s (all threads), points]
    kinds: dict[str, list[float]] = collections.defaultdict(lambda: [0, 0.0, 0.0, 0])

    def run_batch(tables: Any, structure: Any, **kw: Any) -> Any:
        t, c = time.perf_counter(), time.process_time()
        res = plain_run(tables, structure, **kw)
        k = kinds["derivative passes" if kw.get("sensitivities") else "plain runs"]
        k[0] += 1
        k[1] += time.perf_counter() - t
        k[2] += time.process_time() - c
        k[3] += len(res.get("reasons", []))
        if engine:
            e = engine[-1]
            dt = time.perf_counter() - t
            e["engine_s"] += dt
            e["points"] += len(res.get("reasons", []))
            if kw.get("sensitivities"):
                e["derivative_s"] += dt
            used = np.asarray(res.get("dt_used", []), dtype=float)
            e["retried"] += int(np.sum(np.isfinite(used) & (used < 0.99 * kw.get("dt", 0.0))))
            e["diverged"] += int(np.sum(~np.isfinite(used)))
        return res

    case_model.run_batch = run_batch  # type: ignore[attr-defined]

    def fit(objective: fitting.Objective, base: Any, free: Any, **kw: Any) -> Any:
        trace: list[float] = []
        plain_vector = objective.vector

        def vector(preds: Any) -> Any:
            v = plain_vector(preds)
            trace.append(float(v @ v))
            return v

        objective.vector = vector  # type: ignore[method-assign]
        t = time.perf_counter()
        engine.append(dict(engine_s=0.0, points=0, derivative_s=0.0, retried=0, diverged=0))
        try:
            out = plain_fit(objective, base, free, **kw)
        finally:
            del objective.vector
            spent = engine.pop()
            if engine:  # a fit inside a fit: its batches are the outer one's too
                for k, v in spent.items():
                    engine[-1][k] += v
        budget = kw.get("max_nfev", 40)
        half = trace[len(trace) // 2] if trace else np.nan
        rows.append(dict(site=_site(), parts=" / ".join(progress._OPEN.get()), seconds=time.perf_counter() - t,
                         nfev=out.nfev, budget=budget, free=len(free), cycles=objective.cycles, n=objective.n,
                         chi2_first=trace[0] if trace else np.nan, chi2=out.chi2,
                         gain_last_half=(half - min(trace[len(trace) // 2:])) if trace else np.nan,
                         message=out.message, **spent, effects=sorted(getattr(base, "effects", {}) or {}),
                         names=[f.name for f in free], t_end=time.perf_counter() - t0))
        if sink is not None:
            sink.write(json.dumps(rows[-1], default=str) + "\n")
            sink.flush()
        return out

    plain_usable = fitting.usable_derivative
    usable: collections.Counter[str] = collections.Counter()

    def usable_derivative(dpred: Any, pred: Any) -> bool:
        ok = plain_usable(dpred, pred)
        usable["usable" if ok else "not finite" if not np.all(np.isfinite(dpred)) else "blown up"] += 1
        return ok

    for m in modules + [fitting]:
        if getattr(m, "usable_derivative", None) is plain_usable:
            m.usable_derivative = usable_derivative  # type: ignore[attr-defined]
        if getattr(m, "fit", None) is plain_fit:
            m.fit = fit  # type: ignore[attr-defined]
    c0 = time.process_time()
    d = idm_rs.diagnose(a.case, progress=False)
    total = time.perf_counter() - t0
    cpu = time.process_time() - c0
    print(f"verdict {d.verdict} in {total:.1f} s; {len(rows)} fits, {sum(r['seconds'] for r in rows):.1f} s in fits")
    by: dict[str, list[dict[str, Any]]] = collections.defaultdict(list)
    for r in rows:
        by[r["site"]].append(r)
    print("| site | fits | s | nfev used / budget | on budget | chi2 gain, last half of budget-stopped (median) |")
    print("|---|---|---|---|---|---|")
    for site, rs in sorted(by.items(), key=lambda kv: -sum(r["seconds"] for r in kv[1])):
        capped = [r for r in rs if r["nfev"] >= r["budget"]]
        gains = [r["gain_last_half"] for r in capped]
        print(f"| {site} | {len(rs)} | {sum(r['seconds'] for r in rs):.1f} | {sum(r['nfev'] for r in rs)} / "
              f"{sum(r['budget'] for r in rs)} | {len(capped)} | {np.median(gains) if gains else float('nan'):.3g} |")
    print(json.dumps({k: round(v, 1) for k, v in d.timings.items()}))
    print(f"whole diagnosis: {total:.1f} s wall, {cpu:.1f} s CPU ({cpu / total:.2f} cores)")
    for kind, (n, wall, kcpu, pts) in kinds.items():
        print(f"engine {kind}: {int(n)} batches, {int(pts)} points, {wall:.1f} s wall ({wall / total:.0%}), "
              f"{kcpu / wall if wall else math.nan:.2f} cores")
    print("engine derivatives:", dict(usable))
    if sink is not None:
        # the diagnosis itself, to compare with a bench row of the same device
        sink.write(json.dumps({"diagnosis": d.to_dict()}, default=str) + "\n")
        sink.close()


if __name__ == "__main__":
    main()
