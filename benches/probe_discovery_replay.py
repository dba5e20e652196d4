"""Probe: discovery alone, replayed from where a diagnosis entered it.

    python benches/probe_discovery_replay.py save CASE_DIR OUT_DIR [--calls K]
    python benches/probe_discovery_replay.py replay OUT_DIR/call0.pkl [--label L] [--jsonl FILE]

``save`` runs ``idm_rs.diagnose`` on a written device (``bench_discovery_structures.py --only N
--write-only DIR``) and pickles every call of discovery it makes (the recording, the model
discovery starts from, its calibrated subset, the objective, the held-out predictor, the
nominal model) as ``callK.pkl``, before the call runs; it prints the diagnosis's verdict and
seconds. ``replay`` runs discovery on one pickled call, BLAS held to one thread as the
diagnosis holds it, and prints (or appends to ``--jsonl``) its outcome: verdict, the form, RMS
over noise, seconds, and every refit with its start. The pre-discovery stages (most of a
discovery case's time) are paid once per device; a change to discovery is then compared on
the same inputs (the same pickle replayed from two installs side by side, each run under
`--label`; cloudpickle, which dask brings, writes the closures of the fit's setters).
"""

from __future__ import annotations

import argparse
import importlib
import json
import sys
import time
import warnings
from pathlib import Path
from typing import Any

import cloudpickle


class _Saved(Exception):
    """Raised once the calls asked for are pickled: the rest of the diagnosis is not needed."""


def save(case: Path, out: Path, calls_wanted: int = 0) -> None:
    import idm_rs

    dmod = importlib.import_module("idm_rs.diagnosis.diagnose")  # the module (the package exports the function)

    out.mkdir(parents=True, exist_ok=True)
    original = dmod.run_discovery
    calls = [0]

    def recording(*args: Any, **kwargs: Any) -> Any:
        keep = {k: v for k, v in kwargs.items() if k != "progress"}  # the Problem's ticker
        with open(out / f"call{calls[0]}.pkl", "wb") as fh:
            cloudpickle.dump((args, keep), fh)
        calls[0] += 1
        if calls_wanted and calls[0] >= calls_wanted:
            raise _Saved
        return original(*args, **kwargs)

    dmod.run_discovery = recording
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        t0 = time.perf_counter()
        try:
            d = idm_rs.diagnose(case, progress=False)
        except _Saved:
            print(json.dumps({"case": str(case), "saved_calls": calls[0], "seconds": time.perf_counter() - t0}))
            return
    print(json.dumps({"case": str(case), "verdict": d.verdict, "seconds": time.perf_counter() - t0,
                      "discovery_calls": calls[0], "reason": d.reason}))


def replay(pkl: Path) -> dict[str, Any]:
    from threadpoolctl import threadpool_limits

    from idm_rs.diagnosis.discovery import discover

    importlib.import_module("idm_rs.diagnosis.diagnose")._load_every_blas()
    with open(pkl, "rb") as fh:
        args, kwargs = cloudpickle.load(fh)
    with threadpool_limits(limits=1, user_api="blas"), warnings.catch_warnings():
        warnings.simplefilter("ignore")
        t0 = time.perf_counter()
        found = discover(*args, **kwargs)
        seconds = time.perf_counter() - t0
    sigma = args[3].sigma
    return {"call": str(pkl), "discovered": found.discovered, "body": found.body,
            "terms": [t.symbol for t in found.form.terms] if found.form is not None else [],
            "rms_after_over_noise": found.rms_after / sigma if found.refit is not None else None,
            "seconds": seconds, "result": found.to_dict()}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    sub = ap.add_subparsers(dest="what", required=True)
    s = sub.add_parser("save")
    s.add_argument("case", type=Path)
    s.add_argument("out", type=Path)
    s.add_argument("--calls", type=int, default=0, help="stop once this many calls are pickled (0: run to the end)")
    r = sub.add_parser("replay")
    r.add_argument("pkl", type=Path)
    r.add_argument("--jsonl", type=Path)
    r.add_argument("--label", default="")
    a = ap.parse_args()
    if a.what == "save":
        save(a.case, a.out, a.calls)
        return
    row = {"label": a.label, **replay(a.pkl)}
    line = json.dumps(row, default=str)
    if a.jsonl:
        with open(a.jsonl, "a") as fh:
            fh.write(line + "\n")
    print(line)
    sys.stdout.flush()


if __name__ == "__main__":
    main()
