"""Probe: the engine batches of one diagnosis — derivative batches by their number of names, and
the points that ran before bit for bit (what a cache of runs could save).

    python benches/probe_engine_batches.py CASE_DIR

Wraps the diagnosis's `case_model.run_batch`, runs `idm_rs.diagnose` on the recording in
CASE_DIR, and prints: per number of derivative names (0: plain runs) the batches, points and
seconds; then the points and whole batches whose inputs (parameters, effects, drive, span, initial
state and every option but the thread count) had been run before, with the seconds they took (a
point's share of its batch's seconds). A probe, not a test: the diagnosis is the package's,
unchanged.
"""

from __future__ import annotations

import argparse
import collections
import hashlib
import json
import time
from typing import Any

import numpy as np

import idm_rs
from idm_rs.diagnosis import case_model


def _digest(*parts: Any) -> bytes:
    h = hashlib.sha1()
    for p in parts:
        if isinstance(p, np.ndarray):
            h.update(np.ascontiguousarray(p).tobytes())
            h.update(str(p.shape).encode())
        else:
            h.update(repr(p).encode())
    return h.digest()


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("case")
    a = ap.parse_args()
    plain = case_model.run_batch  # type: ignore[attr-defined]
    by_names: dict[int, list[float]] = collections.defaultdict(lambda: [0, 0, 0.0])  # batches, points, s
    seen_points: set[bytes] = set()
    seen_batches: set[bytes] = set()
    repeated = dict(points=0, point_s=0.0, batches=0, batch_s=0.0, all_points=0, all_s=0.0)

    def run_batch(tables: Any, structure: Any, **kw: Any) -> Any:
        t = time.perf_counter()
        res = plain(tables, structure, **kw)
        dt = time.perf_counter() - t
        k = by_names[len(kw.get("sensitivities") or [])]
        k[0] += 1
        k[1] += tables.size
        k[2] += dt
        options = {o: (_digest(v) if isinstance(v, np.ndarray) else v) for o, v in sorted(kw.items()) if o != "threads"}
        shared = _digest(repr(structure), tables.wave_kind, *(tables.sampled or (None, None)), repr(options))
        again = 0
        per_point = (tables.t_ends, tables.t_starts, tables.initial_states)
        for i in range(tables.size):
            key = _digest(shared, tables.params[i], tables.effects[i], tables.wave_fields[i],
                          *(None if x is None else x[i] for x in per_point))
            again += key in seen_points
            seen_points.add(key)
        whole = _digest(shared, tables.params, tables.effects, tables.wave_fields, tables.t_ends, tables.t_starts,
                        tables.initial_states)
        if whole in seen_batches:
            repeated["batches"] += 1
            repeated["batch_s"] += dt
        seen_batches.add(whole)
        repeated["points"] += again
        repeated["point_s"] += dt * again / max(tables.size, 1)
        repeated["all_points"] += tables.size
        repeated["all_s"] += dt
        return res

    case_model.run_batch = run_batch  # type: ignore[attr-defined,assignment]
    t0 = time.perf_counter()
    d = idm_rs.diagnose(a.case, progress=False)
    print(f"verdict {d.verdict} in {time.perf_counter() - t0:.1f} s")
    print("| derivative names | batches | points | s |")
    print("|---:|---:|---:|---:|")
    for n in sorted(by_names):
        b, p, s = by_names[n]
        print(f"| {n} | {int(b)} | {int(p)} | {s:.1f} |")
    print(f"run before, bit for bit: {repeated['points']} of {repeated['all_points']} points "
          f"({repeated['point_s']:.1f} of {repeated['all_s']:.1f} s in the engine), "
          f"{repeated['batches']} whole batches ({repeated['batch_s']:.1f} s)")
    print(json.dumps({k: round(v, 1) for k, v in d.timings.items()}))


if __name__ == "__main__":
    main()
