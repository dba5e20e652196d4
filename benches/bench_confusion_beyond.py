"""The diagnosis beyond one catalogue effect: two effects at once, forces outside the catalogue
that the discovery library can represent, and forces it cannot.

    python benches/bench_confusion_beyond.py --jsonl benches/confusion_beyond_runs.jsonl \
        --out benches/confusion_beyond.md [--kinds pair offcat] [--limit N] [--only ID ...]

* **pair** cases (``PAIRS``; the first three are the unseen devices of issue 31): two catalogue
  effects, each tuned alone to the confusion matrix's large size (8 x noise after a linearised
  refit, ``bench_confusion._tuned``), on the LPS or DPS device of ``bench_confusion`` with 1-3
  calibrated parameters mis-set by 5-15 % in meta.json. Right: the verdict names both
  (``a+b`` in either order).
* **offcat** cases: devices written by the independent simulator (``tests/offcatalogue.py``,
  scipy ``solve_ivp``, not the engine) with dev10's parameters, a force at a random magnitude
  (and wavelength, frequency). In the library (``IN_LIBRARY``): right when the verdict is
  ``discovered`` with a term in the true variable. Off the library (``OFF_LIBRARY``: a floor
  vibration at a random frequency, a compliant base): right when no term is claimed (verdict
  ``unexplained`` or ``not_converged``); a ``discovered`` verdict or a catalogue effect is a
  wrong term.

A line of JSON per finished case goes to ``--jsonl`` (resumable: cases already there are
skipped; the cases are drawn from ``--seed`` in a fixed order). Run it from a separate install.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import math
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
from bench_confusion import EXPERIMENTS, SIZES, _misset, _nominal_of, _true_device, _tuned  # noqa: E402
from bench_rows import append, finished  # noqa: E402

#: two-effect devices (the first three: issue 31's unseen ones)
PAIRS: tuple[tuple[str, str], ...] = (
    ("incline", "spring_to_ground"), ("thermal_drift", "stribeck"), ("sensor_lowpass", "weight_friction"),
    ("incline", "weight_friction"), ("spring_to_ground", "amplifier_lowpass"), ("friction_asymmetry", "thermal_drift"),
    ("piezo_creep", "incline"), ("sensor_lowpass", "spring_to_ground"), ("stribeck", "spring_to_ground"),
    ("weight_friction", "thermal_drift"),
)
#: off-catalogue forces the library can represent: (name, the variable a right term depends on)
IN_LIBRARY = (("periodic_friction", "x1"), ("cubic_spring", "x1"), ("quadratic_drag", "v1"),
              ("voltage_force", "V"), ("weight_dry_friction", "v2"))
#: forces no library term represents
OFF_LIBRARY = ("vibration", "compliant_base")
#: how many of each off-catalogue kind (at different random magnitudes)
OFFCAT_REPEATS = 2


def plan(seed: int) -> list[dict[str, Any]]:
    out: list[dict[str, Any]] = []
    for i, (a, b) in enumerate(PAIRS):
        out.append({"kind": "pair", "effects": [a, b], "device": ("lps", "dps")[i % 2]})
    for r in range(OFFCAT_REPEATS):
        for name, var in IN_LIBRARY:
            out.append({"kind": "offcat", "mechanism": name, "variable": var, "in_library": True, "repeat": r})
        for name in OFF_LIBRARY:
            out.append({"kind": "offcat", "mechanism": name, "variable": "", "in_library": False, "repeat": r})
    for i, c in enumerate(out):
        c["id"] = i
    return out


def pair_case(directory: Path, c: dict[str, Any], rng: np.random.Generator) -> dict[str, Any]:
    """Write a two-effect case, each effect at the large size when alone."""
    return effects_case(directory, c["effects"], c["device"], rng)


def effects_case(directory: Path, effects: list[str], device: str, rng: np.random.Generator,
                 size_range: Optional[tuple[float, float]] = None) -> dict[str, Any]:
    """Write a case with every effect of `effects` on `device`, each tuned alone to a size (RMS
    after a linearised refit, in noise units) drawn from `size_range` (default: the large size,
    SIZES["large"]), 1-3 calibrated parameters mis-set in meta.json."""
    import idm_rs
    from idm_rs.io.synthetic import make_case

    noise = float(rng.uniform(1.0e-9, 2.0e-9))
    seed = int(rng.integers(0, 2**31))
    true0 = idm_rs.Params()
    given, misset = _misset(true0, rng)
    targets = ([float(rng.uniform(*size_range)) for _ in effects] if size_range is not None
               else [SIZES["large"]] * len(effects))
    mags, sizes = {}, {}
    p = true0
    fields: dict[str, float] = {}
    model = nominal_model = device
    for e, target in zip(effects, targets):
        m, size = _tuned(e, device, target, noise)
        pe, eff, model_e, _ = _true_device(e, m, device)
        if e == "stribeck":
            p = p.replace(mu_s=pe.mu_s)
        if e == "piezo_hysteresis":
            p = p.replace(hyst_alpha=pe.hyst_alpha)
        fields.update({k: v for k, v in dataclasses.asdict(eff).items() if v != getattr(idm_rs.Effects(), k)})
        mags[e], sizes[e] = m, size
        model = model_e
    p_true = p.replace(normal_force=p.effective_normal_force)
    nominal = _nominal_of(list(effects), p, true0, given)
    make_case(directory, nominal_params=nominal.replace(normal_force=p_true.normal_force), true_params=p_true,
              model=nominal_model, n_elements=4, piezo_hysteresis=False, true_model=model,
              true_piezo_hysteresis="piezo_hysteresis" in effects, effects=idm_rs.Effects(**fields),
              experiments=EXPERIMENTS, noise_rms=noise, seed=seed, dt=2e-8)
    return {"misset": misset, "magnitude": mags, "size_after_refit": sizes, "noise_rms": noise,
            "truth": "+".join(effects)}


def offcat_case(directory: Path, c: dict[str, Any], rng: np.random.Generator) -> dict[str, Any]:
    """Write an off-catalogue case at a random magnitude with the independent simulator."""
    import offcatalogue as oc

    name = c["mechanism"]
    seed = int(rng.integers(0, 2**31))
    if name == "periodic_friction":
        extra = oc.PeriodicFriction(amplitude=float(rng.uniform(0.01, 0.05)),
                                    wavelength=float(math.exp(rng.uniform(math.log(3e-6), math.log(60e-6)))),
                                    phase=float(rng.uniform(0, 2 * math.pi)))
    elif name == "cubic_spring":
        extra = oc.CubicSpring(k3=float(rng.uniform(1e13, 5e13)))
    elif name == "quadratic_drag":
        extra = oc.QuadraticDrag(c2=float(rng.uniform(500.0, 2000.0)))
    elif name == "voltage_force":
        extra = oc.VoltageForce(c=float(rng.uniform(3e-4, 1.5e-3)))
    elif name == "weight_dry_friction":
        extra = oc.WeightFriction(fw=float(rng.uniform(0.02, 0.1)))
    elif name == "vibration":
        extra = oc.Vibration(amplitude=float(rng.uniform(0.02, 0.08)), frequency=float(rng.uniform(60.0, 300.0)),
                             phase=float(rng.uniform(0, 2 * math.pi)))
    elif name == "compliant_base":
        extra = oc.CompliantBase(mb=float(rng.uniform(1.0, 3.0)), kb=float(rng.uniform(2e9, 8e9)), cb=1e4)
    else:
        raise ValueError(name)
    nominal = {"model": "lps", "piezo_hysteresis": False, "params": dict(oc.DEV10_PARAMS)}
    oc.write_case(directory, nominal, dict(oc.DEV10_PARAMS), oc.case_experiments(), extra=extra, seed=seed,
                  truth={"case": name})
    return {"extra": dataclasses.asdict(extra), "truth": name}


def right(c: dict[str, Any], d: Any) -> bool:
    if c["kind"] == "pair":
        a, b = c["effects"]
        return d.verdict in (f"{a}+{b}", f"{b}+{a}")
    if c["in_library"]:
        found = d.discovery
        variables = found.form.variables if found is not None and found.form is not None else []
        return d.verdict.endswith("discovered") and any(v == c["variable"] or v.startswith(c["variable"])
                                                         for v in variables)
    return d.verdict in ("unexplained", "not_converged")


def _look_alike_right(c: dict[str, Any], d: Any) -> bool:
    """An in-library case discovered as the true term's look-alike, the true term named beside
    it as one the data cannot choose from (counted apart from `right`)."""
    found = d.discovery
    if c["kind"] != "offcat" or not c["in_library"] or found is None or found.look_alike is None:
        return False
    form = found.look_alike.form
    return d.verdict.endswith("discovered") and form is not None and any(
        v == c["variable"] or v.startswith(c["variable"]) for v in form.variables)


def run_case(c: dict[str, Any], tmp: Path, seed: int) -> dict[str, Any]:
    import idm_rs

    rng = np.random.default_rng([seed, 1000 + c["id"]])
    directory = tmp / f"case{c['id']:03d}"
    info = pair_case(directory, c, rng) if c["kind"] == "pair" else offcat_case(directory, c, rng)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        t0 = time.perf_counter()
        d = idm_rs.diagnose(directory, progress=False)
        seconds = time.perf_counter() - t0
    found = d.discovery
    return {**c, **info, "verdict": d.verdict, "right": right(c, d), "seconds": seconds,
            "calibrated_over_noise": d.rms_calibrated / d.noise.sigma, "after_over_noise": d.rms_after / d.noise.sigma,
            "terms": [t.symbol for t in found.form.terms] if found is not None and found.form is not None else [],
            # a look-alike refitted in the found form's place that fits as well: the verdict names both
            "look_alike_terms": ([t.symbol for t in found.look_alike.form.terms]
                                 if found is not None and found.look_alike is not None
                                 and found.look_alike.form is not None else []),
            "right_with_look_alike": right(c, d) or _look_alike_right(c, d),
            "reason": d.reason,
            "shares": d.second.shares if d.second is not None else {},
            "discovery_seconds": found.seconds if found is not None else 0.0, "timings": dict(d.timings)}


def _bound(k: int, n: int) -> str:
    """k of n with the 95 % Clopper-Pearson interval of the rate."""
    from scipy.stats import beta

    lo = float(beta.ppf(0.025, k, n - k + 1)) if k > 0 else 0.0
    hi = float(beta.ppf(0.975, k + 1, n - k)) if k < n else 1.0
    return f"{k} of {n} ({100 * k / n:.0f} %, 95 % interval {100 * lo:.0f}-{100 * hi:.0f} %)" if n else "none run"


def table(rows: list[dict[str, Any]]) -> str:
    lines = ["| id | kind | truth | verdict | right | terms | RMS calibrated / after (x noise) | s |",
             "|---|---|---|---|---|---|---|---|"]
    for r in sorted(rows, key=lambda r: r["id"]):
        lines.append(f"| {r['id']} | {r['kind']} | {r['truth']} | {r['verdict']} | {'✓' if r['right'] else '✗'} | "
                     f"{', '.join(r.get('terms') or []) or '–'} | {r['calibrated_over_noise']:.2f} / "
                     f"{r['after_over_noise']:.2f} | {r['seconds']:.0f} |")
    pairs = [r for r in rows if r["kind"] == "pair"]
    inlib = [r for r in rows if r["kind"] == "offcat" and r["in_library"]]
    offlib = [r for r in rows if r["kind"] == "offcat" and not r["in_library"]]
    wrong_terms = sum(r["verdict"] not in ("unexplained", "not_converged") for r in offlib)
    lines += ["", f"- both effects named: {_bound(sum(r['right'] for r in pairs), len(pairs))}",
              "- in-library forces discovered with the right variable: "
              f"{_bound(sum(r['right'] for r in inlib), len(inlib))}; with the right variable or as its "
              "look-alike with the right one named beside it: "
              f"{_bound(sum(r['right'] or r.get('right_with_look_alike', False) for r in inlib), len(inlib))}",
              f"- off-library forces given a term or an effect (must be 0): {_bound(wrong_terms, len(offlib))}"]
    if rows:
        secs = [r["seconds"] for r in rows]
        lines.append(f"- time per case: median {np.median(secs):.0f} s, max {max(secs):.0f} s")
    return "\n".join(lines) + "\n"


def main(argv: Optional[list[str]] = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--kinds", nargs="+", default=["pair", "offcat"])
    ap.add_argument("--limit", type=int)
    ap.add_argument("--only", type=int, nargs="+", metavar="ID")
    ap.add_argument("--jsonl", type=Path, required=True)
    ap.add_argument("--out", type=Path)
    a = ap.parse_args(argv)

    done = {r["id"] for r in finished(a.jsonl)}
    todo = [c for c in plan(a.seed) if c["id"] not in done and c["kind"] in a.kinds
            and (a.only is None or c["id"] in a.only)][: a.limit]
    with tempfile.TemporaryDirectory() as tmp:
        for c in todo:
            row = run_case(c, Path(tmp), a.seed)
            print(json.dumps(row, default=str), flush=True)
            append(a.jsonl, row)
    md = table(finished(a.jsonl))
    print(md)
    if a.out:
        a.out.write_text(md)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
