"""A late channel against its look-alike lags, under a reading coarser than its noise: healthy
devices whose channel is 2-20 us late, read at a resolution of 2-5 x the noise, must come out
`none`; devices with a sensor lag or an amplifier lag (the delay's look-alikes), read as coarsely,
must still have the lag named.

    python benches/bench_delay_lookalike.py --jsonl F [--seed 0] [--per-structure 4] \
        [--only ID ...] [--summary] [--code COMMIT]

Healthy: LPS, LPS + h, DPS 4, DPS 4 + h alike (`--per-structure` each), 1-4 calibrated nominal
values mis-set by 5-15 % (``bench_realism.py``'s draws), white noise 1-2 nm, the delay and the
resolution drawn as that bench draws them. Effects: ``sensor_lowpass`` and ``amplifier_lowpass``
on the LPS and the DPS at the large and the small size of ``bench_confusion.py`` (the signal
after a linearised refit 8 and 3 x the noise), white noise, a resolution of 2-5 x the noise.
Rows are appended to ``--jsonl`` as cases finish (resumable); run it from a separate install.
"""

from __future__ import annotations

import argparse
import sys
import tempfile
from pathlib import Path
from typing import Any, Optional

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from bench_confusion import _key_error, diagnosed, effect_case
from bench_realism import false_alarms_line, healthy_case, wilson
from bench_rows import append, finished

STRUCTURES = (("lps", False), ("lps", True), ("dps", False), ("dps", True))
LAGS = ("sensor_lowpass", "amplifier_lowpass")


def plan(per_structure: int) -> list[dict[str, Any]]:
    """The healthy devices structure by structure, then the lag devices."""
    out: list[dict[str, Any]] = [{"kind": "healthy", "structure": list(s)} for _ in range(per_structure)
                                 for s in STRUCTURES]
    out += [{"kind": "effect", "effect": e, "device": d, "size": size}
            for size in ("large", "small") for e in LAGS for d in ("lps", "dps")]
    for i, c in enumerate(out):
        c["id"] = i
    return out


def run_case(c: dict[str, Any], tmp: Path, seed: int) -> dict[str, Any]:
    rng = np.random.default_rng([seed, 7919, c["id"]])
    directory = tmp / f"case{c['id']:03d}"
    if c["kind"] == "healthy":
        info = healthy_case(directory, rng, artefacts=["delay", "resolution"],
                            structure=(c["structure"][0], bool(c["structure"][1])))
        truth = "none"
    else:
        coarse = float(rng.uniform(2.0, 5.0))
        info = effect_case(directory, c, rng, resolution=lambda sigma: coarse * sigma)
        info["resolution"] = coarse * info["noise_rms"]
        truth = c["effect"]
    d, seconds = diagnosed(directory)
    m = d.noise.model
    return {**c, **info, "truth": truth, "verdict": d.verdict, "right": d.verdict == truth, "seconds": seconds,
            "alternatives": list(getattr(d, "alternatives", []) or []),
            "calibrated_over_noise": d.rms_calibrated / d.noise.sigma, "after_over_noise": d.rms_after / d.noise.sigma,
            "key_error": _key_error(d, c, info) if c["kind"] == "effect" else None,
            "delay_applied": bool(m is not None and m.delay_applied),
            "delay_estimate": m.delay_s if m is not None else None,
            "noise": m.describe() if m is not None else "", "reason": d.reason}


def _lookalike(r: dict[str, Any]) -> bool:
    """The other lag named: the pair cannot be told apart, so it counts as found."""
    return r["kind"] == "effect" and set(r["verdict"].split("+")) == set(LAGS) - {r["effect"]}


def summary(rows: list[dict[str, Any]]) -> str:
    healthy = [r for r in rows if r["kind"] == "healthy"]
    effects = [r for r in rows if r["kind"] == "effect"]
    out = [false_alarms_line("healthy, a late channel read coarsely", healthy), "",
           "| id | structure | delay [us] | resolution / noise | verdict | delay taken (estimate) | s |",
           "|---|---|---|---|---|---|---|"]
    for r in healthy:
        model, hyst = r["structure"]
        est = r.get("delay_estimate")
        out.append(f"| {r['id']} | {model.upper()}{' + h' if hyst else ''} | {1e6 * r['sensor']['delay_s']:.1f} | "
                   f"{r['resolution'] / r['noise_rms']:.1f} | {r['verdict']} | "
                   f"{'yes' if r['delay_applied'] else 'no'} ({1e6 * est:.1f}) | {r['seconds']:.0f} |"
                   if est is not None else f"| {r['id']} | {model} | - | - | {r['verdict']} | - | - |")
    if effects:
        ok = sum(1 for r in effects if r["right"] or _lookalike(r))
        lo, hi = wilson(ok, len(effects))
        out += ["", f"lags read coarsely: {ok} of {len(effects)} named or their look-alike "
                f"({100 * lo:.0f}-{100 * hi:.0f} %)", "",
                "| id | effect | device | size | resolution / noise | verdict | after / noise | key error | s |",
                "|---|---|---|---|---|---|---|---|---|"]
        for r in effects:
            ke = f"{100 * r['key_error']:+.1f} %" if r.get("key_error") is not None else "-"
            out.append(f"| {r['id']} | {r['effect']} | {r['device']} | {r['size']} | "
                       f"{r['resolution'] / r['noise_rms']:.1f} | {r['verdict']} | {r['after_over_noise']:.2f} | "
                       f"{ke} | {r['seconds']:.0f} |")
    return "\n".join(out)


def main(argv: Optional[list[str]] = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--jsonl", type=Path, required=True)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--per-structure", type=int, default=4)
    ap.add_argument("--only", type=int, nargs="+", metavar="ID", help="run these cases only")
    ap.add_argument("--summary", action="store_true", help="print the table of the finished cases and stop")
    ap.add_argument("--code", default="", help="the commit the diagnosis runs (kept in every row)")
    a = ap.parse_args(argv)
    if a.summary:
        print(summary(finished(a.jsonl)))
        return 0
    with tempfile.TemporaryDirectory() as tmp:
        for c in plan(a.per_structure):
            if c["id"] in {r["id"] for r in finished(a.jsonl)} or (a.only is not None and c["id"] not in a.only):
                continue
            row = {**run_case(c, Path(tmp), a.seed), "code": a.code}
            append(a.jsonl, row)
            print(f"{row['id']:3d} {row['truth']:>18s} -> {row['verdict']:<20s} {row['seconds']:5.0f} s "
                  f"{row['noise']}", flush=True)
    print(summary(finished(a.jsonl)))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
