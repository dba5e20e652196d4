"""The diagnosis on recordings as a lab makes them: healthy devices whose reading carries one or
two artefacts (coloured or pink noise, spikes, a coarse resolution, mains hum, a late channel, a
drifting zero), and catalogue effects under coloured noise or spikes.

    python benches/bench_realism.py --jsonl benches/realism_runs.jsonl [--healthy 100] \
        [--limit N] [--shard K/N] [--only ID ...] [--summary]

Healthy devices: LPS, LPS with piezo hysteresis, DPS (n = 4), DPS with hysteresis, drawn alike;
1-4 of the calibrated nominal values mis-set by 5-15 % in meta.json; noise 1-2 nm; each with one
or two artefacts at random levels: AR(1) noise of lag-1 0.5-0.95, pink (1/f) noise making
50-100 % of the variance, 2-10 spikes per file of 15-30 sigma, a resolution of 2-5 x the noise,
a 50 or 60 Hz hum of 0.5-2 sigma, a channel delay of 2-20 us, a zero drifting 5-30 nm per file.
A false alarm is any verdict but "none". The noise model reported is compared with the truth
(marginal level, lag-1, line amplitude, delay, spikes).

Effects: every catalogue effect at the large size of ``bench_confusion.py`` (its signal after a
linearised refit 8 x the noise RMS) on the LPS and the DPS, under AR(1) noise (lag-1 0.5-0.95)
or 2-10 spikes per file of 15-30 sigma, alternately. Cases are drawn from ``--seed`` in a fixed
order; one JSON line per finished case goes to ``--jsonl`` (resumable; two ``--shard`` processes
can share one file). Run it from a separate install: a case takes a diagnosis's time.
"""

from __future__ import annotations

import argparse
import math
import sys
import tempfile
from pathlib import Path
from typing import Any, Optional

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from bench_confusion import _key_error, _margin, diagnosed, effect_case
from bench_false_alarm import EXPERIMENTS
from bench_rows import append, finished, shard
from idm_rs.diagnosis.thresholds import CALIBRATED

ARTEFACTS = ("ar1", "pink", "spikes", "resolution", "hum", "delay", "drift")
EFFECTS = ("piezo_hysteresis", "stribeck", "incline", "spring_to_ground", "amplifier_lowpass", "piezo_creep",
           "weight_friction", "friction_asymmetry", "sensor_lowpass", "thermal_drift", "pe_mass")


def plan(healthy: int) -> list[dict[str, Any]]:
    """Healthy devices with an effect case after every fourth (the rest of each at the end)."""
    effects = [{"kind": "effect", "effect": e, "device": d, "size": "large",
                "artefact": ("ar1", "spikes")[(i + j) % 2]}
               for i, e in enumerate(EFFECTS) for j, d in enumerate(("lps", "dps"))
               if not (e == "pe_mass" and d == "dps")]
    out: list[dict[str, Any]] = []
    k = 0
    for h in range(healthy):
        out.append({"kind": "healthy", "index": h})
        if h % 4 == 3 and k < len(effects):
            out.append(effects[k])
            k += 1
    out += effects[k:]
    for i, c in enumerate(out):
        c["id"] = i
    return out


def draw_artefacts(rng: np.random.Generator, sigma: float, names: list[str]) -> tuple[dict[str, Any], float]:
    """(SensorNoise arguments, resolution [m]) for the artefacts `names` at random levels."""
    kw: dict[str, Any] = {"rms": sigma}
    resolution = 2.5e-10
    for a in names:
        if a == "ar1":
            kw["ar"] = (float(rng.uniform(0.5, 0.95)),)
        elif a == "pink":
            kw["pink"] = float(rng.uniform(0.5, 1.0))
        elif a == "spikes":
            kw["outliers"] = int(rng.integers(2, 11))
            kw["outlier_sigmas"] = (15.0, 30.0)
        elif a == "resolution":
            resolution = float(rng.uniform(2.0, 5.0)) * sigma
        elif a == "hum":
            kw["hum"] = ((float(rng.choice([50.0, 60.0])), float(rng.uniform(0.5, 2.0)) * sigma),)
        elif a == "delay":
            kw["delay_s"] = float(rng.uniform(2e-6, 20e-6))
        elif a == "drift":
            kw["drift_m"] = (5e-9, 30e-9)
    return kw, resolution


def healthy_case(directory: Path, rng: np.random.Generator, artefacts: Optional[list[str]] = None,
                 structure: Optional[tuple[str, bool]] = None) -> dict[str, Any]:
    """A healthy device with mis-set nominal values and one or two artefacts, all drawn from
    `rng`; `artefacts` and `structure` ((model, piezo hysteresis)) replace the drawn ones (the
    draws are made all the same, so a seed's other devices do not change)."""
    import idm_rs
    from idm_rs.io.sensor_noise import SensorNoise
    from idm_rs.io.synthetic import make_case

    true = idm_rs.Params()
    names = rng.choice(CALIBRATED, size=int(rng.integers(1, 5)), replace=False)
    misset = {str(n): float(rng.choice([-1, 1]) * rng.uniform(0.05, 0.15)) for n in names}
    given = {n: getattr(true, n) * (1 + f) for n, f in misset.items()}
    if "mu_k" in given:
        given["mu_k"] = min(given["mu_k"], 0.99 * true.mu_s)
    nominal = true.replace(**given, normal_force=true.effective_normal_force)
    model = str(rng.choice(["lps", "dps"]))
    hyst = bool(rng.integers(0, 2))
    sigma = float(rng.uniform(1.0e-9, 2.0e-9))
    pool = list(ARTEFACTS)
    first = str(rng.choice(pool))
    arts = [first]
    if rng.uniform() < 0.5:
        rest = [a for a in pool if a != first and {a, first} != {"ar1", "pink"}]
        arts.append(str(rng.choice(rest)))
    arts = arts if artefacts is None else list(artefacts)
    model, hyst = (model, hyst) if structure is None else structure
    kw, resolution = draw_artefacts(rng, sigma, arts)
    make_case(directory, nominal_params=nominal, true_params=true.replace(normal_force=true.effective_normal_force),
              model=model, n_elements=4, piezo_hysteresis=hyst, experiments=EXPERIMENTS,
              noise=SensorNoise(**kw), resolution=resolution, seed=int(rng.integers(0, 2**31)), dt=2e-8)
    return {"misset": misset, "model": model, "piezo_hysteresis": hyst, "artefacts": arts,
            "sensor": _jsonable(kw), "resolution": resolution, "noise_rms": sigma}


def _jsonable(kw: dict[str, Any]) -> dict[str, Any]:
    return {k: (list(v) if isinstance(v, tuple) else v) for k, v in kw.items()}


def noise_truth(c: dict[str, Any]) -> dict[str, Any]:
    """What the noise model should report: marginal RMS, lag-1, line amplitude, delay."""
    s = c.get("sensor", {})
    sigma = s.get("rms", c.get("noise_rms"))
    res = c.get("resolution", 0.0) or 0.0
    # a reading coarser than its noise: the rounding error (resolution^2 / 12) is noise too
    out: dict[str, Any] = {"sigma": math.sqrt(sigma**2 + res**2 / 12.0) if res > sigma else sigma}
    ar = s.get("ar") or []
    # under a reading coarser than its noise the rounding error is part of the reading's noise,
    # correlated where the coloured noise moves less than a step: the reading's lag-1 is neither
    # the sensor's nor a mixture with white rounding, so no truth to hold it to
    out["lag1"] = ar[0] if ar and not res > sigma else None
    out["line"] = s["hum"][0][1] if s.get("hum") else None
    out["delay"] = s.get("delay_s")
    out["spikes"] = 3 * s["outliers"] if s.get("outliers") else None
    return out


def run_case(c: dict[str, Any], tmp: Path, seed: int) -> dict[str, Any]:
    from idm_rs.io.sensor_noise import SensorNoise

    rng = np.random.default_rng([seed, c["id"]])
    directory = tmp / f"case{c['id']:03d}"
    if c["kind"] == "healthy":
        info = healthy_case(directory, rng)
        truth = "none"
    else:
        lag = float(rng.uniform(0.5, 0.95))
        spikes = int(rng.integers(2, 11))

        def sensor(sigma: float) -> Any:
            if c["artefact"] == "ar1":
                return SensorNoise(rms=sigma, ar=(lag,))
            return SensorNoise(rms=sigma, outliers=spikes)

        info = effect_case(directory, c, rng, sensor=sensor)
        info["sensor"] = ({"rms": info["noise_rms"], "ar": [lag]} if c["artefact"] == "ar1"
                          else {"rms": info["noise_rms"], "outliers": spikes})
        truth = c["effect"]
    d, seconds = diagnosed(directory)
    m = d.noise.model
    reported = {"sigma": d.noise.sigma, "lag1": m.lag1 if m is not None else None,
                "line": m.lines[0][1] if m is not None and m.lines else None,
                "delay": m.delay_s if m is not None and m.delay_applied else None,
                "delay_estimate": m.delay_s if m is not None else None,
                "spikes": m.outliers if m is not None else None,
                "drift_applied": bool(m is not None and m.drift_m), "summary": m.describe() if m is not None else "",
                "notes": list(m.notes) if m is not None else []}
    return {**c, **info, "truth": truth, "verdict": d.verdict, "right": d.verdict == truth, "seconds": seconds,
            "calibrated_over_noise": d.rms_calibrated / d.noise.sigma, "after_over_noise": d.rms_after / d.noise.sigma,
            "key_error": _key_error(d, c, info) if c["kind"] == "effect" else None,
            "reason": d.reason, "noise_truth": noise_truth({**c, **info}), "noise_reported": reported, **_margin(d),
            "timings": dict(d.timings), "timings_parts": dict(d.timings_parts)}


def wilson(k: int, n: int) -> tuple[float, float]:
    """95 % Wilson interval of a rate k / n."""
    if n == 0:
        return math.nan, math.nan
    z = 1.959964
    p = k / n
    c = (p + z * z / (2 * n)) / (1 + z * z / n)
    h = z * math.sqrt(p * (1 - p) / n + z * z / (4 * n * n)) / (1 + z * z / n)
    return max(0.0, c - h), min(1.0, c + h)


def false_alarms_line(what: str, healthy: list[dict[str, Any]]) -> str:
    """'`what`: n; false alarms k (95 % bounds ...)': any verdict but none on a healthy device."""
    fa = sum(1 for r in healthy if r["verdict"] != "none")
    lo, hi = wilson(fa, len(healthy))
    return f"{what}: {len(healthy)}; false alarms {fa} (95 % bounds {100 * lo:.1f}-{100 * hi:.1f} %)"


def _within(rep: Optional[float], true: Optional[float], tol: float = 0.2) -> Optional[bool]:
    if true is None or not true:
        return None
    if rep is None:
        return False  # there, and not found
    return abs(rep / true - 1.0) <= tol


def summary(rows: list[dict[str, Any]]) -> str:
    """The bench's table (markdown)."""
    rows = [{**r, "noise_truth": noise_truth(r)} for r in rows]
    healthy = [r for r in rows if r["kind"] == "healthy"]
    effects = [r for r in rows if r["kind"] == "effect"]
    out = [false_alarms_line("healthy devices with artefacts", healthy), "",
           "| artefact | cases | none | other verdicts | noise model within 20 % (level / lag-1 / line / delay) |",
           "|---|---|---|---|---|"]
    for a in ARTEFACTS:
        rs = [r for r in healthy if a in r["artefacts"]]
        if not rs:
            continue
        others = ", ".join(sorted(f"{r['verdict']}" for r in rs if r["verdict"] != "none")) or "-"
        key = {"ar1": "lag1", "pink": "sigma", "hum": "line", "delay": "delay"}.get(a, "sigma")
        ok = [_within(r["noise_reported"].get(key), r["noise_truth"].get(key)) for r in rs]
        ok_n = [o for o in ok if o is not None]
        lvl = f"{sum(ok_n)}/{len(ok_n)} ({key})" if ok_n else "-"
        out.append(f"| {a} | {len(rs)} | {sum(1 for r in rs if r['verdict'] == 'none')} | {others} | {lvl} |")
    no_hum = [r for r in healthy if "hum" not in r["artefacts"]]
    spurious = [r for r in no_hum if r["noise_reported"].get("line") is not None]
    out += ["", f"a hum line reported on a device without hum: {len(spurious)} of {len(no_hum)}"
            + (" (" + ", ".join(f"case {r['id']}: {'+'.join(r['artefacts'])}" for r in spurious) + ")"
               if spurious else "")]
    if effects:
        right = sum(1 for r in effects if r["right"])
        lo, hi = wilson(right, len(effects))
        out += ["", f"catalogue effects at 8 x noise under coloured noise or spikes: {right} of {len(effects)} right "
                f"({100 * lo:.0f}-{100 * hi:.0f} %)", "",
                "| effect | device | artefact | verdict | after / noise | key error |", "|---|---|---|---|---|---|"]
        for r in effects:
            ke = f"{100 * r['key_error']:+.0f} %" if r.get("key_error") is not None else "-"
            out.append(f"| {r['effect']} | {r['device']} | {r['artefact']} | {r['verdict']} | "
                       f"{r['after_over_noise']:.2f} | {ke} |")
    secs = [r["seconds"] for r in rows]
    if secs:
        out += ["", f"seconds per case: median {np.median(secs):.0f}, max {max(secs):.0f}"]
    return "\n".join(out)


def main(argv: Optional[list[str]] = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--jsonl", type=Path, required=True)
    ap.add_argument("--healthy", type=int, default=100)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--limit", type=int)
    ap.add_argument("--shard", type=shard, default=(0, 1), metavar="K/N")
    ap.add_argument("--only", type=int, nargs="+", metavar="ID", help="run these cases only")
    ap.add_argument("--summary", action="store_true", help="print the table of the finished cases and stop")
    ap.add_argument("--code", default="", help="the commit the diagnosis runs (kept in every row)")
    a = ap.parse_args(argv)

    if a.summary:
        print(summary(finished(a.jsonl)))
        return 0
    k, n = a.shard
    cases = plan(a.healthy)[: a.limit]
    with tempfile.TemporaryDirectory() as tmp:
        for c in cases:
            if (c["id"] % n != k or c["id"] in {r["id"] for r in finished(a.jsonl)}
                    or (a.only is not None and c["id"] not in a.only)):
                continue
            row = {**run_case(c, Path(tmp), a.seed), "code": a.code}
            row["noise_truth"] = noise_truth(row)
            append(a.jsonl, row)
            print(f"{c['id']:3d} {row['truth']:>20s} -> {row['verdict']:<20s} {row['seconds']:5.0f} s "
                  f"{row['noise_reported']['summary']}", flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
