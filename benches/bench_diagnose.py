"""Time and score `idm_rs.diagnose` on the recorded dev sets against their KEY.json.

    python benches/bench_diagnose.py ../shared/recordings/dev ../shared/recordings/dev2 \
        --out benches/diagnose_results.md [--jsonl runs.jsonl] [--cases dev04 d2_07]

Each case runs in this process one after another (the engine uses every core), and a line of
JSON per finished case is appended to ``--jsonl`` as it finishes, so an interrupted run keeps
what it measured; cases already in that file are skipped when it is given again. The markdown
table has, per case: the key, the verdict, whether it is right, the residual RMS over the noise
before (nominal) / calibrated / after (refit), the key parameter against the truth, the time.
Run it from a separate install (a wheel in its own venv) so that rebuilding the package cannot
change it under a long run.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import platform
import statistics
import sys
import time
import warnings
from pathlib import Path
from typing import Any, Optional


def key_parameter(key: dict[str, Any], d: dict[str, Any]) -> tuple[str, Optional[float]]:
    """'name fitted vs true (error %)' for the verdict's effect parameters, and the worst
    relative error (None when the key has no fitted parameter or the verdict is wrong)."""
    if d["verdict"] != key["expected_verdict"] or not key.get("params"):
        return "", None
    cand = next((c for c in d["ranking"] if c["effect"] == d["verdict"]), None)
    if cand is None:
        return "", None
    parts, worst = [], 0.0
    for name, truth in key["params"].items():
        v = cand["params"].get(name)
        if v is None or not isinstance(truth, (int, float)) or truth == 0:
            continue
        err = v / truth - 1.0
        worst = max(worst, abs(err))
        parts.append(f"{name} {v:.4g} vs {truth:.4g} ({100 * err:+.1f} %)")
    return "; ".join(parts), (worst if parts else None)


def run_case(case: Path, key: dict[str, Any]) -> dict[str, Any]:
    import idm_rs

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        t0 = time.perf_counter()
        d = idm_rs.diagnose(case, progress=False).to_dict()
        seconds = time.perf_counter() - t0
    sigma = d["noise_rms"]
    text, worst = key_parameter(key, d)
    return {
        "case": case.name, "set": case.parent.name, "key": key["expected_verdict"], "verdict": d["verdict"],
        "right": d["verdict"] == key["expected_verdict"], "before": d["rms_before"] / sigma,
        "calibrated": d["rms_calibrated"] / sigma, "after": d["rms_after"] / sigma, "key_parameter": text,
        "worst_parameter_error": worst, "seconds": seconds, "converged": d["calibration"]["converged"],
        "reason": d["reason"], "timings": d["timings"], "timings_parts": d.get("timings_parts", {}),
        # discovery ran (the catalogue left a systematic residual) and what it concluded
        "discovery_ran": d.get("discovery") is not None,
        "discovered": bool(d.get("discovery") and d["discovery"]["discovered"]),
        "discovery_seconds": (d.get("discovery") or {}).get("seconds", 0.0),
    }


def table(rows: list[dict[str, Any]]) -> str:
    head = ("| set | case | key | verdict | right | discovered | RMS before / calibrated / after (× noise) | "
            "key parameter (fitted vs true) | s |\n|---|---|---|---|---|---|---|---|---|")
    lines = [head]
    for r in rows:
        disc = ("yes" if r.get("discovered") else "ran, no" if r.get("discovery_ran") else "–")
        lines.append(f"| {r['set']} | {r['case']} | {r['key']} | {r['verdict']} | {'✓' if r['right'] else '✗'} | "
                     f"{disc} | {r['before']:.2f} / {r['calibrated']:.2f} / {r['after']:.2f} | {r['key_parameter']} | "
                     f"{r['seconds']:.0f} |")
    right = sum(r["right"] for r in rows)
    healthy = [r for r in rows if r["key"] == "none"]
    false_alarms = sum(r["verdict"] not in ("none",) for r in healthy)
    times = sorted(r["seconds"] for r in rows)
    med = statistics.median(times) if times else math.nan
    lines.append("")
    named = sum(r['verdict'] not in ('none', 'unexplained', 'not_converged') for r in healthy)
    lines.append(f"{right} of {len(rows)} right; healthy devices: {len(healthy)}, false alarms (an effect named on a "
                 f"healthy device) {named}, "
                 f"not 'none' {false_alarms}; discovered on {sum(bool(r.get('discovered')) for r in rows)} "
                 f"(on a healthy device {sum(bool(r.get('discovered')) for r in healthy)}); time median {med:.0f} s, "
                 f"max {max(times) if times else math.nan:.0f} s")
    return "\n".join(lines)


def main(argv: Optional[list[str]] = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("sets", nargs="+", type=Path, help="directories holding case folders and KEY.json")
    ap.add_argument("--cases", nargs="*", help="only these case names")
    ap.add_argument("--out", type=Path, help="write the markdown table here")
    ap.add_argument("--jsonl", type=Path, help="append one JSON line per finished case (and resume from it)")
    a = ap.parse_args(argv)
    done: dict[tuple[str, str], dict[str, Any]] = {}
    if a.jsonl and a.jsonl.exists():
        for line in a.jsonl.read_text().splitlines():
            r = json.loads(line)
            done[(r["set"], r["case"])] = r
    rows = []
    for s in a.sets:
        keys = json.loads((s / "KEY.json").read_text())
        for name in sorted(keys):
            if a.cases and name not in a.cases:
                continue
            if (s.name, name) in done:
                rows.append(done[(s.name, name)])
                continue
            r = run_case(s / name, keys[name])
            rows.append(r)
            print(f"{r['set']}/{r['case']}: {r['verdict']} ({'right' if r['right'] else 'WRONG'}) "
                  f"in {r['seconds']:.0f} s", flush=True)
            if a.jsonl:
                with a.jsonl.open("a") as f:
                    f.write(json.dumps(r) + "\n")
    import idm_rs

    md = (f"Command: `python {' '.join(sys.argv)}`\n\nidm_rs {idm_rs.__version__}, {os.cpu_count()} CPUs, "
          f"{platform.processor() or platform.machine()}, {time.strftime('%Y-%m-%d %H:%M')}\n\n" + table(rows) + "\n")
    print(md)
    if a.out:
        a.out.write_text(md)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
