"""Several catalogue effects at once, where the catalogue has look-alikes: two-effect devices
with one effect drawn from a near-parallel pair, and devices with three effects.

    python benches/bench_effect_sets.py --jsonl benches/effect_sets_runs.jsonl \
        [--kinds lookalike_pair triple] [--limit N] [--only ID ...] [--shard K/N] [--code COMMIT]
    python benches/bench_effect_sets.py --jsonl ... --summary

* **lookalike_pair** (``LOOKALIKE_DEVICES``): one effect of a near-parallel pair (``TWINS``:
  incline ~ friction asymmetry, amplifier lag ~ sensor lag) and one other catalogue effect,
  each tuned alone to 6-8 x noise after a linearised refit of the calibrated subset, on the LPS
  or the DPS 4 of ``bench_confusion`` with 1-3 calibrated parameters mis-set 5-15 %. Right: the
  verdict names both, or the twin in the drawn one's place; **named**: the twin of whichever of
  the pair the verdict names appears in ``alternatives`` (it must, every time).
* **triple** (``TRIPLE_DEVICES``): three distinct catalogue effects (at most one of each
  near-parallel pair), each at 6-8 x noise. Right: all three named, a twin standing in for its
  partner where the partner is in ``alternatives``; **wrong**: an effect named that is neither
  one of the three nor a twin of one (it must never happen).

A line of JSON per finished case goes to ``--jsonl`` (resumable). Run it from a separate install.
"""

from __future__ import annotations

import argparse
import sys
import tempfile
import time
import warnings
from pathlib import Path
from typing import Any, Optional

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))
sys.path.insert(0, str(HERE.parent / "tests"))
from bench_confusion_beyond import _bound, effects_case  # noqa: E402
from bench_rows import append, finished, shard  # noqa: E402

#: the catalogue's near-parallel pairs (degenerate on the standard experiments: |cos| 0.95-0.99)
TWINS: dict[str, str] = {"incline": "friction_asymmetry", "friction_asymmetry": "incline",
                         "amplifier_lowpass": "sensor_lowpass", "sensor_lowpass": "amplifier_lowpass"}
#: effects a device may carry (pe_mass changes the structure: left out)
EFFECTS: tuple[str, ...] = ("piezo_hysteresis", "stribeck", "incline", "spring_to_ground", "amplifier_lowpass",
                            "piezo_creep", "weight_friction", "friction_asymmetry", "sensor_lowpass",
                            "thermal_drift")
LOOKALIKE_DEVICES = 10
TRIPLE_DEVICES = 10
#: each effect's size alone after a linearised refit, in noise units
SIZE_RANGE = (6.0, 8.0)


def _allowed(effects: list[str]) -> bool:
    """At most one of each near-parallel pair (a device with both cannot be told from either)."""
    return not any(TWINS.get(a) == b for a in effects for b in effects)


def plan(seed: int) -> list[dict[str, Any]]:
    rng = np.random.default_rng([seed, 51])
    out: list[dict[str, Any]] = []
    twins = sorted(TWINS)
    for i in range(LOOKALIKE_DEVICES):
        a, device = twins[i % len(twins)], ("lps", "dps")[i % 2]
        used = {c["effects"][1] for c in out if c["effects"][0] == a and c["device"] == device}
        b = str(rng.choice([e for e in EFFECTS if e not in (a, TWINS[a]) and e not in used]))
        out.append({"kind": "lookalike_pair", "effects": [a, b], "device": device})
    for i in range(TRIPLE_DEVICES):
        while True:
            three = [str(e) for e in rng.choice(EFFECTS, size=3, replace=False)]
            if _allowed(three):
                break
        out.append({"kind": "triple", "effects": three, "device": ("lps", "dps")[i % 2]})
    for i, c in enumerate(out):
        c["id"] = i
    return out


def judged(effects: list[str], verdict: str, alternatives: list[str], separated: Optional[list[str]] = None
           ) -> dict[str, Any]:
    """How a verdict on a device with `effects` reads: every true effect named or stood in for by
    its twin (the true one then among `alternatives`), no effect named beyond them and their
    twins, and every named effect that has a twin reported with it: the twin among
    `alternatives`, or refitted in its place and separated by the data (`separated`: "a~b", b
    refitted in place of a left a systematic residual, which the reason says)."""
    named = [v for v in verdict.split("+") if v] if verdict not in ("none", "unexplained", "not_converged") else []
    accounted = all(e in named or (TWINS.get(e) in named and e in alternatives) for e in effects)
    allowed = set(effects) | {TWINS[e] for e in effects if e in TWINS}
    wrong = [v for v in named if v not in allowed]
    twin_named = [v for v in named if v in TWINS]
    return {"named": named, "right": accounted and not wrong, "wrong_effects": wrong,
            "look_alike_reported": all(TWINS[v] in alternatives or f"{v}~{TWINS[v]}" in (separated or [])
                                       for v in twin_named) if twin_named else None}


def run_case(c: dict[str, Any], tmp: Path, seed: int) -> dict[str, Any]:
    import idm_rs

    rng = np.random.default_rng([seed, 5100 + c["id"]])
    directory = tmp / f"case{c['id']:03d}"
    info = effects_case(directory, c["effects"], c["device"], rng, SIZE_RANGE)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        t0 = time.perf_counter()
        d = idm_rs.diagnose(directory, progress=False)
        seconds = time.perf_counter() - t0
    alts = [a.effect for a in d.alternatives]
    twins = [t for search in (d.second, d.third) if search is not None for t in search.twins]
    separated = [f"{t.member}~{t.twin}" for t in twins if not t.stands]
    return {**c, **info, "verdict": d.verdict, "alternatives": alts, "twins_separated": separated,
            **judged(c["effects"], d.verdict, alts, separated),
            "seconds": seconds, "calibrated_over_noise": d.rms_calibrated / d.noise.sigma,
            "after_over_noise": d.rms_after / d.noise.sigma, "reason": d.reason, "timings": dict(d.timings),
            "timings_parts": dict(d.timings_parts),
            # the share of the calibrated null's misfit above noise the second round's pair took
            # (a third effect is searched only beside a pair with a third of it)
            "pair_misfit_share": d.second.misfit_share if d.second is not None else float("nan"),
            "third_searched": d.third is not None}


def summary(rows: list[dict[str, Any]]) -> str:
    lines = ["| id | kind | device | truth | verdict | alternatives | right | after / noise | s |",
             "|---|---|---|---|---|---|---|---|---|"]
    for r in sorted(rows, key=lambda r: r["id"]):
        lines.append(f"| {r['id']} | {r['kind']} | {r['device']} | {r['truth']} | {r['verdict']} | "
                     f"{', '.join(r['alternatives']) or '-'} | {'yes' if r['right'] else 'no'} | "
                     f"{r['after_over_noise']:.2f} | {r['seconds']:.0f} |")
    pairs = [r for r in rows if r["kind"] == "lookalike_pair"]
    triples = [r for r in rows if r["kind"] == "triple"]
    reported = [r["look_alike_reported"] for r in rows if r["look_alike_reported"] is not None]
    lines += ["", f"- look-alike pairs, both named or the twin in the drawn one's place: "
              f"{_bound(sum(r['right'] for r in pairs), len(pairs))}",
              f"- a named effect with a twin reported with it in `alternatives`: "
              f"{_bound(sum(reported), len(reported))}",
              f"- three effects, all named or stood in for by a stated twin: "
              f"{_bound(sum(r['right'] for r in triples), len(triples))}",
              f"- cases naming an effect that is neither true nor a twin of one (must be 0): "
              f"{sum(1 for r in rows if r['wrong_effects'])} of {len(rows)}"]
    if rows:
        secs = [r["seconds"] for r in rows]
        lines.append(f"- time per case: median {np.median(secs):.0f} s, max {max(secs):.0f} s")
    return "\n".join(lines) + "\n"


def main(argv: Optional[list[str]] = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--kinds", nargs="+", default=["lookalike_pair", "triple"])
    ap.add_argument("--limit", type=int)
    ap.add_argument("--only", type=int, nargs="+", metavar="ID")
    ap.add_argument("--shard", type=shard, default=(0, 1), metavar="K/N")
    ap.add_argument("--code", default="", help="the commit the diagnosis runs (kept in every row)")
    ap.add_argument("--jsonl", type=Path, required=True)
    ap.add_argument("--summary", action="store_true", help="print the table of the finished cases and stop")
    a = ap.parse_args(argv)

    if a.summary:
        print(summary(finished(a.jsonl)))
        return 0
    k, n = a.shard
    done = {r["id"] for r in finished(a.jsonl)}
    todo = [c for c in plan(a.seed) if c["id"] not in done and c["kind"] in a.kinds and c["id"] % n == k
            and (a.only is None or c["id"] in a.only)][: a.limit]
    with tempfile.TemporaryDirectory() as tmp:
        for c in todo:
            row = {**run_case(c, Path(tmp), a.seed), "code": a.code}
            append(a.jsonl, row)
            print(f"{c['id']:3d} {row['truth']:>55s} -> {row['verdict']:<40s} {row['seconds']:5.0f} s "
                  f"alternatives {row['alternatives']}", flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
