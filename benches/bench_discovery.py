"""The whole diagnosis on devices with physics outside the catalogue, written by an independent
simulator (scipy ``solve_ivp``, ``tests/offcatalogue.py``): what discovery finds, the residual
before and after, the held-out experiment, the time.

    python benches/bench_discovery.py --work /tmp/offcat --jsonl benches/discovery_runs.jsonl \
        [--cases quadratic_drag none] [--short] [--seed 1]

Cases: the four mechanisms of ``OFF_CATALOGUE_CASES`` (position-periodic friction, a cubic
spring to ground, quadratic drag on the main body, a compliant sliding base) and ``none`` (the
same device with nothing extra: discovery must not run, or find nothing). A line of JSON per
finished case is appended to ``--jsonl`` (cases already there are skipped), and the markdown
table is printed. Run from a separate install when timing.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
import warnings
from pathlib import Path
from typing import Any, Optional

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parent / "tests"))

#: the variable each mechanism's force depends on (what a right answer names)
TRUTH = {"periodic_friction": "x1", "cubic_spring": "x1", "quadratic_drag": "v1", "compliant_base": "base",
         "none": ""}


def run_case(name: str, work: Path, seed: int, short: bool) -> dict[str, Any]:
    import idm_rs
    from offcatalogue import make_offcatalogue_case

    case = work / (name + ("_short" if short else ""))
    if not (case / "meta.json").exists():
        make_offcatalogue_case(name, case, seed=seed, short=short)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        t0 = time.perf_counter()
        d = idm_rs.diagnose(case, progress=False)
        seconds = time.perf_counter() - t0
    out = d.to_dict()
    disc = out.get("discovery") or {}
    sigma = out["noise_rms"]
    return {
        "case": name, "short": short, "truth_variable": TRUTH[name], "verdict": out["verdict"],
        "terms": disc.get("terms", []), "variables": disc.get("variables", []),
        "description": disc.get("description", ""), "values": disc.get("values", {}),
        "before": out["rms_before"] / sigma, "calibrated": out["rms_calibrated"] / sigma,
        "after": out["rms_after"] / sigma,
        "heldout_before": disc.get("heldout_rms_before", float("nan")) / sigma,
        "heldout_after": disc.get("heldout_rms_after", float("nan")) / sigma,
        "delta_bic": disc.get("delta_bic", float("nan")), "seconds": seconds,
        "discovery_seconds": disc.get("seconds", 0.0), "reason": out["reason"],
        "timings": out["timings"],
    }


def right(r: dict[str, Any]) -> bool:
    """A found term depends on the right variable (healthy: nothing discovered)."""
    if r["case"] == "none":
        return r["verdict"] == "none"
    want = r["truth_variable"]
    return r["verdict"] == "discovered" and any(v == want or v.startswith(want) for v in r["variables"])


def table(rows: list[dict[str, Any]]) -> str:
    lines = ["| case | verdict | term found (refitted) | depends on (truth) | right | RMS before / calibrated / after "
             "(× noise) | held-out before → after (× noise) | discovery s | total s |",
             "|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        lines.append(
            f"| {r['case']}{' (short)' if r['short'] else ''} | {r['verdict']} | {r['description'] or '–'} | "
            f"{', '.join(r['variables']) or '–'} ({r['truth_variable'] or 'nothing'}) | {'✓' if right(r) else '✗'} | "
            f"{r['before']:.2f} / {r['calibrated']:.2f} / {r['after']:.2f} | "
            f"{r['heldout_before']:.2f} → {r['heldout_after']:.2f} | {r['discovery_seconds']:.0f} | "
            f"{r['seconds']:.0f} |")
    n_right = sum(right(r) for r in rows)
    noise = sum(1 for r in rows if r["case"] != "none" and r["verdict"] == "discovered" and r["after"] <= 1.2)
    lines.append("")
    lines.append(f"{n_right} of {len(rows)} right; refit within 1.2 × noise on {noise} of "
                 f"{sum(r['case'] != 'none' for r in rows)} off-catalogue cases")
    return "\n".join(lines)


def main(argv: Optional[list[str]] = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--work", type=Path, default=Path("/tmp/idm-offcatalogue"), help="where the cases are written")
    ap.add_argument("--jsonl", type=Path, default=None, help="append one line per finished case; resume from it")
    ap.add_argument("--cases", nargs="*", default=list(TRUTH), help="case names (default: all)")
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--short", action="store_true", help="2 drive cycles per experiment")
    a = ap.parse_args(argv)
    a.work.mkdir(parents=True, exist_ok=True)
    done: dict[str, dict[str, Any]] = {}
    if a.jsonl is not None and a.jsonl.exists():
        for line in a.jsonl.read_text().splitlines():
            if line.strip():
                r = json.loads(line)
                done[r["case"] + ("_short" if r["short"] else "")] = r
    rows = []
    for name in a.cases:
        key = name + ("_short" if a.short else "")
        if key in done:
            rows.append(done[key])
            continue
        r = run_case(name, a.work, a.seed, a.short)
        rows.append(r)
        print(f"{name}: {r['verdict']} {r['description']!r} in {r['seconds']:.0f} s", flush=True)
        if a.jsonl is not None:
            with a.jsonl.open("a") as fh:
                fh.write(json.dumps(r) + "\n")
    print(table(rows))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
