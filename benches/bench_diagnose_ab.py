"""Whole diagnoses through two copies of the package (two engines), one after the other, and
whether each diagnosis came out the same to the last digit: how an engine change that must not
move a result is measured on the diagnosis (a ratio taken in one session on one machine).

    python benches/bench_diagnose_ab.py BEFORE AFTER CASE_DIR [CASE_DIR ...] [--repeats 1]
        [--jsonl OUT]

BEFORE and AFTER are directories that hold an ``idm_rs`` package with its built ``_core`` (a
snapshot: ``git archive HEAD python | tar -x -C DIR`` and the built ``.so`` copied in). Each
case is diagnosed by each copy in a fresh process (before, after, before, ... with
``--repeats``), nothing else should run beside it. Printed: per case the seconds of each copy,
their ratio, and whether the diagnoses (``Diagnosis.to_dict()`` without its clocks) are
identical (else the first paths that differ); with ``--jsonl``, one line per case as it
finishes. Exits 1 if any pair differs.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

#: the diagnosis in a child process: its dictionary without the clocks (every "seconds",
#: "timings" and "timings_parts" at any depth), and its wall seconds
CHILD = """
import json, sys, time
import idm_rs
t = time.perf_counter()
d = idm_rs.diagnose(sys.argv[1], progress=False)
w = time.perf_counter() - t
CLOCKS = ("seconds", "timings", "timings_parts")
def unclocked(x):
    if isinstance(x, dict):
        return {k: unclocked(v) for k, v in x.items() if k not in CLOCKS}
    if isinstance(x, (list, tuple)):
        return [unclocked(v) for v in x]
    return x
print(json.dumps({"wall": w, "diagnosis": unclocked(d.to_dict())}, default=str, sort_keys=True))
"""


def diagnose(package: str, case: str) -> dict[str, Any]:
    """One diagnosis of `case` by the package in directory `package` (a fresh interpreter)."""
    env = {**os.environ, "PYTHONPATH": str(Path(package).resolve())}
    res = subprocess.run([sys.executable, "-c", CHILD, case], env=env, capture_output=True, text=True, check=True)
    out: dict[str, Any] = json.loads(res.stdout.strip().splitlines()[-1])
    return out


def differences(a: Any, b: Any, path: str = "") -> list[str]:
    """The paths at which `a` and `b` (JSON values) differ; a NaN equals a NaN (a field with no
    value, e.g. a correlation of a parameter without curvature, is the same in both)."""
    if isinstance(a, dict) and isinstance(b, dict):
        return [p for k in sorted(set(a) | set(b)) for p in differences(a.get(k), b.get(k), f"{path}.{k}")]
    if isinstance(a, list) and isinstance(b, list) and len(a) == len(b):
        return [p for i, (x, y) in enumerate(zip(a, b)) for p in differences(x, y, f"{path}[{i}]")]
    if isinstance(a, float) and isinstance(b, float) and math.isnan(a) and math.isnan(b):
        return []
    return [] if a == b else [path or "."]


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("before")
    ap.add_argument("after")
    ap.add_argument("cases", nargs="+")
    ap.add_argument("--repeats", type=int, default=1)
    ap.add_argument("--jsonl")
    a = ap.parse_args(argv)
    sink = open(a.jsonl, "a") if a.jsonl else None
    differ = 0
    print("| case | verdict | before [s] | after [s] | after / before | same diagnosis |")
    print("|---|---|---:|---:|---:|---|")
    for case in a.cases:
        walls: dict[str, list[float]] = {"before": [], "after": []}
        seen: dict[str, Any] = {}
        for _ in range(a.repeats):
            for name in ("before", "after"):
                r = diagnose(getattr(a, name), case)
                walls[name].append(r["wall"])
                seen[name] = r["diagnosis"]
        where = differences(seen["before"], seen["after"])
        same = not where
        differ += not same
        b, f = min(walls["before"]), min(walls["after"])
        print(f"| {Path(case).name} | {seen['after'].get('verdict')} | {b:.1f} | {f:.1f} | {f / b:.2f} | "
              f"{'yes' if same else 'NO: ' + ', '.join(where[:5])} |", flush=True)
        if sink is not None:
            row = {"case": case, "verdict": seen["after"].get("verdict"), "before_s": walls["before"],
                   "after_s": walls["after"], "same": same, "differences": where, "at": time.time()}
            sink.write(json.dumps(row) + "\n")
            sink.flush()
    return 1 if differ else 0


if __name__ == "__main__":
    sys.exit(main())
