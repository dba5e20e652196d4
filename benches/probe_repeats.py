"""Probe: does a diagnosis fit or simulate the same thing twice? (What a cache would save.)

    python benches/probe_repeats.py CASE_DIR

Wraps the diagnosis's `fit` (in every module that imported it) and `CaseSimulator.predict`, runs
`idm_rs.diagnose` on the recording in CASE_DIR, and prints how many fits and predicted models
were repeats of an earlier one with the same inputs (a fit: its objective, the model, every free
parameter's start, bounds and scale, its evaluation budget; a model: its every parameter and the
horizon), the seconds the repeated fits took, and the seconds per stage. A probe, not a test:
the wrapped diagnosis is the package's, unchanged.
"""

from __future__ import annotations

import collections
import importlib
import json
import pkgutil
import sys
import time
import traceback
from typing import Any

import idm_rs
import idm_rs.diagnosis as diagnosis
from idm_rs.diagnosis import fitting
from idm_rs.diagnosis.case_model import CaseSimulator


def main(case: str) -> None:
    modules = [importlib.import_module(m.name) for m in pkgutil.walk_packages(diagnosis.__path__, "idm_rs.diagnosis.")]
    plain_fit, plain_predict = fitting.fit, CaseSimulator.predict
    fits: collections.Counter[Any] = collections.Counter()
    repeated_s: collections.Counter[str] = collections.Counter()
    fit_s = [0.0]
    models: collections.Counter[Any] = collections.Counter()

    def objective_key(o: fitting.Objective) -> Any:
        return id(o.recording), o.cycles, o.segmented, tuple(o.experiments), o.sigma, repr(o.measurement)

    def fit(objective: fitting.Objective, base: Any, free: Any, **kw: Any) -> Any:
        key = (objective_key(objective), repr(base),
               tuple((f.name, f.x0, f.lower, f.upper, f.scale, f.log, f.setter.__qualname__) for f in free),
               kw.get("max_nfev"), kw.get("fd_step"))
        t = time.perf_counter()
        out = plain_fit(objective, base, free, **kw)
        dt = time.perf_counter() - t
        fit_s[0] += dt
        if fits[key]:
            caller = traceback.extract_stack(limit=2)[0]
            repeated_s[f"{caller.filename.rsplit('/', 1)[-1]}:{caller.lineno}"] += dt
        fits[key] += 1
        return out

    def predict(self: CaseSimulator, specs: Any, cycles: Any = None, *args: Any, **kw: Any) -> Any:
        for s in specs:
            models[(id(self), repr(s), cycles)] += 1
        return plain_predict(self, specs, cycles, *args, **kw)

    for m in modules + [fitting]:
        if getattr(m, "fit", None) is plain_fit:
            m.fit = fit  # type: ignore[attr-defined]
    CaseSimulator.predict = predict  # type: ignore[method-assign]
    t0 = time.perf_counter()
    d = idm_rs.diagnose(case, progress=False)
    print(f"verdict {d.verdict} in {time.perf_counter() - t0:.1f} s")
    print(f"fits {sum(fits.values())}, distinct {len(fits)}; {fit_s[0]:.1f} s in fits, "
          f"{sum(repeated_s.values()):.1f} s in repeated ones")
    for where, s in repeated_s.most_common():
        print(f"  repeated at {where}: {s:.1f} s")
    n = sum(models.values())
    print(f"models predicted {n}, repeats {n - len(models)} ({100 * (n - len(models)) / max(n, 1):.1f} %)")
    print(json.dumps({k: round(v, 1) for k, v in d.timings.items()}))


if __name__ == "__main__":
    if len(sys.argv) != 2:
        raise SystemExit(__doc__)
    main(sys.argv[1])
