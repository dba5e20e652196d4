"""Measure the diagnosis's false-alarm rate on simulated null recordings: devices that lack
nothing (the nominal model is right up to mis-set nominal values), with the noise of a real
recording. Each null case is written by ``idm_rs.io.synthetic.make_case`` from Table 1 with 1–3 of
the calibrated parameters mis-set in ``meta.json`` by 5–15 % (as in the dev sets), and diagnosed;
a false alarm is any verdict naming an effect. For every null case the largest ΔBIC of a
candidate whose parameters are beyond 2σ of "no effect" is recorded: the decision threshold
(``diagnosis.results.BIC_THRESHOLD``) must sit above (nearly) all of them.

    python benches/bench_false_alarm.py --cases 12 --seed 0 --out benches/false_alarm.md \
        [--jsonl false_alarm.jsonl]

One line of JSON per finished case goes to ``--jsonl`` (resumable). Run it from a separate
install; each case takes about as long as a diagnosis (tens of seconds to minutes).
"""

from __future__ import annotations

import argparse
import json
import math
import tempfile
import time
import warnings
from pathlib import Path
from typing import Any, Optional

import numpy as np

#: experiments of a null case: both directions, two frequencies (a dev-set-like record, shorter)
EXPERIMENTS = (
    {"amplitude_V": 80, "frequency_Hz": 200, "direction": "forward", "cycles": 3},
    {"amplitude_V": 60, "frequency_Hz": 200, "direction": "backward", "cycles": 3},
    {"amplitude_V": 100, "frequency_Hz": 100, "direction": "forward", "cycles": 2},
)
CALIBRATED = ("mu_k", "d33", "sigma1", "sigma2", "fric_alpha", "m1", "m2")


def null_case(directory: Path, rng: np.random.Generator) -> dict[str, Any]:
    """Write one null case; returns what was mis-set and the structure."""
    import idm_rs
    from idm_rs.io.synthetic import make_case

    true = idm_rs.Params()
    names = rng.choice(CALIBRATED, size=int(rng.integers(1, 4)), replace=False)
    misset = {str(n): float(rng.choice([-1, 1]) * rng.uniform(0.05, 0.15)) for n in names}
    given = {n: getattr(true, n) * (1 + f) for n, f in misset.items()}
    if "mu_k" in given:
        given["mu_k"] = min(given["mu_k"], 0.99 * true.mu_s)  # keep the nominal's Stribeck peak
    nominal = true.replace(**given, normal_force=true.effective_normal_force)
    model = str(rng.choice(["lps", "dps"]))
    hyst = bool(rng.integers(0, 2))
    make_case(directory, nominal_params=nominal, true_params=true.replace(normal_force=true.effective_normal_force),
              model=model, n_elements=4, piezo_hysteresis=hyst, experiments=EXPERIMENTS,
              noise_rms=float(rng.uniform(1.0e-9, 2.0e-9)), seed=int(rng.integers(0, 2**31)), dt=2e-8)
    return {"misset": misset, "model": model, "piezo_hysteresis": hyst}


def main(argv: Optional[list[str]] = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--cases", type=int, default=12)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--out", type=Path)
    ap.add_argument("--jsonl", type=Path)
    a = ap.parse_args(argv)
    import idm_rs
    from idm_rs.diagnosis.thresholds import BIC_THRESHOLD

    rows: list[dict[str, Any]] = []
    if a.jsonl and a.jsonl.exists():
        rows = [json.loads(x) for x in a.jsonl.read_text().splitlines()]
    rng = np.random.default_rng(a.seed)
    with tempfile.TemporaryDirectory() as tmp:
        for i in range(a.cases):
            info = null_case(Path(tmp) / f"null{i:02d}", rng)  # drawn even when resumed: same cases
            if i < len(rows):
                continue
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                t0 = time.perf_counter()
                d = idm_rs.diagnose(Path(tmp) / f"null{i:02d}", progress=False)
            present = [c for c in d.ranking if c.present and not c.screened_only]
            row = {"case": i, **info, "verdict": d.verdict, "seconds": time.perf_counter() - t0,
                   "calibrated_over_noise": d.rms_calibrated / d.noise.sigma,
                   "max_delta_bic_present": max((c.delta_bic for c in present), default=-math.inf),
                   "best_present": present[0].effect if present else None}
            rows.append(row)
            print(json.dumps(row), flush=True)
            if a.jsonl:
                with a.jsonl.open("a") as f:
                    f.write(json.dumps(row) + "\n")
    alarms = sum(r["verdict"] not in ("none", "unexplained", "not_converged") for r in rows)
    not_none = sum(r["verdict"] != "none" for r in rows)
    n = len(rows)
    # one-sided 95 % upper bound of a binomial rate with `alarms` events (exact, Clopper-Pearson)
    from scipy.stats import beta

    upper = float(beta.ppf(0.95, alarms + 1, n - alarms)) if n else math.nan
    lines = [f"null cases: {n}; false alarms (an effect named): {alarms} (rate {alarms / max(n, 1):.3f}, 95 % upper "
             f"bound {upper:.3f}); verdict other than 'none': {not_none}; threshold ΔBIC {BIC_THRESHOLD:g}", "",
             "| case | mis-set | model | verdict | calibrated / noise | largest ΔBIC of a present candidate | s |",
             "|---|---|---|---|---|---|---|"]
    for r in rows:
        ms = ", ".join(f"{k} {100 * v:+.0f} %" for k, v in r["misset"].items())
        lines.append(f"| {r['case']} | {ms} | {r['model']}{' + h' if r['piezo_hysteresis'] else ''} | {r['verdict']} | "
                     f"{r['calibrated_over_noise']:.2f} | {r['max_delta_bic_present']:.1f} "
                     f"({r['best_present'] or '–'}) | {r['seconds']:.0f} |")
    md = "\n".join(lines) + "\n"
    print(md)
    if a.out:
        a.out.write_text(md)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
