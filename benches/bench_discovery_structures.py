"""Discovery on every structure a recording can declare: forces outside the catalogue, written by
the independent simulator (``tests/offcatalogue.py``: scipy ``solve_ivp``, not the engine) on the
LPS, the LPS with piezo hysteresis, the DPS of 4 elements and the DPS 4 with hysteresis.

    python benches/bench_discovery_structures.py --jsonl benches/discovery_structures_runs.jsonl \
        [--repeats 1] [--limit N] [--only ID ...] [--shard K/N] [--code COMMIT] [--write-only DIR]
    python benches/bench_discovery_structures.py --summary --jsonl FILE [FILE ...]

`--summary` takes several files (the rows of both seeds, say) and counts them together; each
row is told apart by its seed (kept in every row; older rows without one take it from the file
name, ``..._seed1_...``, else 0), and a device run again counts once, as the file named later
has it (list the re-runs after the first runs).

Each device: dev10's parameters on one structure, 1-3 calibrated parameters mis-set by 5-15 % in
meta.json, white noise of 1-2 nm, and one force at a size drawn uniformly in 6-12 x noise
*after a linearised refit of the calibrated parameters* (what a calibration cannot absorb: the
force's signal from the independent simulator, projected off the engine's Jacobian of the
calibrated subset on that structure; the coefficient found by a secant on that size). The
in-library forms (``IN_LIBRARY``: V, x1^2, x1^3, v1|v1|, v1, friction periodic in x1 over a short
and a long period, dry friction on the weight) are right when the verdict is ``discovered`` with
a term in the true variable; the off-library forms (a floor vibration, a compliant base) are
right when no term and no effect is claimed (``unexplained`` or ``not_converged``). The order
interleaves the structures, so a partial run covers all four.

A line of JSON per finished case goes to ``--jsonl`` (resumable: cases already there are
skipped), with the seconds per stage (``timings``). Run it from a separate install.
"""

from __future__ import annotations

import argparse
import dataclasses
import math
import re
import sys
import tempfile
from pathlib import Path
from typing import Any, Optional

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))
sys.path.insert(0, str(HERE.parent / "tests"))
from bench_confusion import _misset, diagnosed  # noqa: E402
from bench_confusion_beyond import _bound, _look_alike_right, right  # noqa: E402
from bench_rows import append, finished, shard, stage_shares  # noqa: E402

#: (name, model, piezo hysteresis)
STRUCTURES: tuple[tuple[str, str, bool], ...] = (
    ("lps", "lps", False), ("lps_h", "lps", True), ("dps4", "dps", False), ("dps4_h", "dps", True))
#: in-library forms: (name, the variable a right term depends on)
IN_LIBRARY: tuple[tuple[str, str], ...] = (
    ("voltage_force", "V"), ("quadratic_spring", "x1"), ("cubic_spring", "x1"), ("quadratic_drag", "v1"),
    ("linear_drag", "v1"), ("periodic_friction_short", "x1"), ("periodic_friction_long", "x1"),
    ("weight_dry_friction", "v2"))
#: forms no library term represents
OFF_LIBRARY: tuple[str, ...] = ("vibration", "compliant_base")
#: the size after a linearised refit of the calibrated subset, in noise units
SIZE_RANGE = (6.0, 12.0)


def plan(repeats: int) -> list[dict[str, Any]]:
    """Every form on every structure, `repeats` times; structures innermost."""
    out: list[dict[str, Any]] = []
    for r in range(repeats):
        for name, var in IN_LIBRARY + tuple((n, "") for n in OFF_LIBRARY):
            for s, model, hyst in STRUCTURES:
                out.append({"kind": "offcat", "mechanism": name, "variable": var, "in_library": bool(var),
                            "structure": s, "model": model, "piezo_hysteresis": hyst, "repeat": r})
    for i, c in enumerate(out):
        c["id"] = i
    return out


def unit_extra(name: str, rng: np.random.Generator) -> Any:
    """The force `name` at a unit reference coefficient (its shape drawn: wavelength, phase,
    frequency); :func:`scaled` sets its size."""
    import offcatalogue as oc

    if name == "voltage_force":
        return oc.VoltageForce(c=1e-3)
    if name == "quadratic_spring":
        return oc.QuadraticSpring(k2=1e8)
    if name == "cubic_spring":
        return oc.CubicSpring(k3=3e13)
    if name == "quadratic_drag":
        return oc.QuadraticDrag(c2=1e3)
    if name == "linear_drag":
        return oc.LinearDrag(c1=10.0)
    if name == "periodic_friction_short":
        return oc.PeriodicFriction(amplitude=0.03, wavelength=float(rng.uniform(3e-6, 6e-6)),
                                   phase=float(rng.uniform(0, 2 * math.pi)))
    if name == "periodic_friction_long":
        return oc.PeriodicFriction(amplitude=0.03, wavelength=float(rng.uniform(30e-6, 60e-6)),
                                   phase=float(rng.uniform(0, 2 * math.pi)))
    if name == "weight_dry_friction":
        return oc.WeightFriction(fw=0.05)
    if name == "vibration":
        return oc.Vibration(amplitude=0.05, frequency=float(rng.uniform(60.0, 300.0)),
                            phase=float(rng.uniform(0, 2 * math.pi)))
    if name == "compliant_base":
        return oc.CompliantBase(mb=float(rng.uniform(1.0, 3.0)), kb=float(rng.uniform(2e9, 8e9)), cb=1e4)
    raise ValueError(name)


#: the field that sets each force's size (a compliant base: its stiffness, softer is larger)
_SIZE_FIELD = {"VoltageForce": "c", "QuadraticSpring": "k2", "CubicSpring": "k3", "QuadraticDrag": "c2",
               "LinearDrag": "c1", "PeriodicFriction": "amplitude", "WeightFriction": "fw", "Vibration": "amplitude"}


def scaled(extra: Any, factor: float) -> Any:
    """`extra` with its size field times `factor` (a periodic friction's amplitude kept < 0.5)."""
    field = _SIZE_FIELD.get(type(extra).__name__)
    if field is None:
        return extra  # a compliant base: its drawn stiffness is its size
    value = getattr(extra, field) * factor
    if field == "amplitude" and type(extra).__name__ == "PeriodicFriction":
        value = max(min(value, 0.5), -0.5)
    return dataclasses.replace(extra, **{field: value})


def _runs(structure: tuple[str, bool], params: dict[str, float], extra: Any) -> list[np.ndarray]:
    """x1 of the independent simulator on each experiment at 100 kHz."""
    import offcatalogue as oc

    out = []
    for e in oc.case_experiments():
        bt, bv = oc.sawtooth_breakpoints(e["amplitude_V"], e["frequency_Hz"], e["cycles"], e["edge_s"],
                                         e["direction"], e["rest_s"])
        duration = e["rest_s"] + e["cycles"] / e["frequency_Hz"]
        t = np.arange(int(round(duration * 1e5)) + 1) / 1e5
        out.append(oc.simulate_device(params, bt, bv, duration, t, model=structure[0], n_elements=4,
                                      piezo_hysteresis=structure[1], extra=extra)["x1"])
    return out


def tuned(c: dict[str, Any], extra: Any, target: float, noise: float) -> tuple[Any, float]:
    """(the force at the size `target` x `noise` after a linearised refit of the calibrated
    subset, the size reached) on the case's structure; secant on the coefficient."""
    import idm_rs
    import offcatalogue as oc
    from idm_rs.diagnosis.case_model import CaseSimulator, ModelSpec, Structure
    from idm_rs.diagnosis.fitting import FreeParam, Objective, set_param
    from idm_rs.diagnosis.thresholds import CALIBRATED, CALIBRATION_SCALE
    from idm_rs.io.recording import load_case

    structure = (c["model"], c["piezo_hysteresis"])
    p = idm_rs.Params(**oc.DEV10_PARAMS)
    with tempfile.TemporaryDirectory() as tmp:
        oc.write_case(Path(tmp) / "n", {"model": c["model"], "n_elements": 4, "piezo_hysteresis": structure[1],
                                        "params": dict(oc.DEV10_PARAMS)}, dict(oc.DEV10_PARAMS),
                      oc.case_experiments(), noise_rms=0.0, resolution=0.0)
        rec = load_case(Path(tmp) / "n")
    obj = Objective(rec, CaseSimulator(rec), noise)
    spec = ModelSpec(Structure(c["model"], 4 if c["model"] == "dps" else 1, structure[1]), p.to_dict(resolved=False),
                     {})
    free = [FreeParam(n, float(getattr(p, n)), 0.6 * getattr(p, n), 1.5 * getattr(p, n),
                      CALIBRATION_SCALE * getattr(p, n), set_param(n)) for n in CALIBRATED]
    _, J, _ = obj.jacobian(spec, free, np.zeros(len(free)))
    Q, _ = np.linalg.qr(J)
    plain = obj.vector(_runs(structure, dict(oc.DEV10_PARAMS), None))

    def size(x: Any) -> float:
        d = obj.vector(_runs(structure, dict(oc.DEV10_PARAMS), x)) - plain
        d = d - Q @ (Q.T @ d)
        return float(np.linalg.norm(d) / math.sqrt(d.size))

    s = size(extra)
    if type(extra).__name__ not in _SIZE_FIELD:
        return extra, s
    for _ in range(4):
        if not (math.isfinite(s) and s > 0) or abs(s / target - 1) < 0.1:
            break
        extra = scaled(extra, min(max(target / s, 0.05), 20.0))
        s = size(extra)
    return extra, s


def write_device(directory: Path, c: dict[str, Any], rng: np.random.Generator) -> dict[str, Any]:
    """The case's recording: the force at its drawn size on its structure, parameters mis-set."""
    import idm_rs
    import offcatalogue as oc

    noise = float(rng.uniform(1.0e-9, 2.0e-9))
    target = float(rng.uniform(*SIZE_RANGE))
    seed = int(rng.integers(0, 2**31))
    true = idm_rs.Params(**oc.DEV10_PARAMS)
    given, misset = _misset(true, rng)
    extra, reached = tuned(c, unit_extra(c["mechanism"], rng), target, noise)
    nominal = {"model": c["model"], "n_elements": 4, "piezo_hysteresis": c["piezo_hysteresis"],
               "params": {**oc.DEV10_PARAMS, **given}}
    oc.write_case(directory, nominal, dict(oc.DEV10_PARAMS), oc.case_experiments(), extra=extra, noise_rms=noise,
                  seed=seed, truth={"case": c["mechanism"], "structure": c["structure"]})
    return {"extra": dataclasses.asdict(extra), "truth": c["mechanism"], "noise_rms": noise, "misset": misset,
            "size_target": target, "size_after_refit": reached}


def run_case(c: dict[str, Any], tmp: Path, seed: int, diagnose: bool = True) -> dict[str, Any]:

    rng = np.random.default_rng([seed, 2000 + c["id"]])
    directory = tmp / f"case{c['id']:03d}"
    info = write_device(directory, c, rng)
    if not diagnose:
        return {**c, **info}
    d, seconds = diagnosed(directory)
    found = d.discovery
    out = d.to_dict()
    return {**c, **info, "verdict": d.verdict, "right": right(c, d), "seconds": seconds,
            "right_with_look_alike": right(c, d) or _look_alike_right(c, d),
            "calibrated_over_noise": d.rms_calibrated / d.noise.sigma, "after_over_noise": d.rms_after / d.noise.sigma,
            "terms": [t.symbol for t in found.form.terms] if found is not None and found.form is not None else [],
            "reason": d.reason, "timings": out.get("timings", {}), "timings_parts": out.get("timings_parts", {}),
            "discovery_seconds": found.seconds if found is not None else 0.0,
            # every refit of every form discovery tried (start, RMS over noise, evaluations, seconds),
            # the path taken and the one before it
            "discovery_forms": [x.summary() for x in ([found, *found.tried] if found is not None else [])],
            "discovery_other_forms": [x.summary() for x in ([d.discovery_other, *d.discovery_other.tried]
                                                            if d.discovery_other is not None else [])],
            "whiteness_z_after": found.whiteness_z if found is not None else math.nan,
            # the share of the calibrated null's misfit above noise the second round's pair took
            # (a third effect is searched only beside a pair with a third of it)
            "pair_misfit_share": d.second.misfit_share if d.second is not None else math.nan,
            "third_searched": d.third is not None}


def summary(rows: list[dict[str, Any]]) -> str:
    lines = ["| structure | in-library discovered (right variable) | with a look-alike named | "
             "off-library given a term or effect (must be 0) | median / max s |", "|---|---|---|---|---|"]
    for s, _, _ in STRUCTURES:
        mine = [r for r in rows if r["structure"] == s and "verdict" in r]
        inlib = [r for r in mine if r["in_library"]]
        offlib = [r for r in mine if not r["in_library"]]
        wrong = sum(r["verdict"] not in ("unexplained", "not_converged") for r in offlib)
        secs = [r["seconds"] for r in mine]
        lines.append(f"| {s} | {_bound(sum(r['right'] for r in inlib), len(inlib))} | "
                     f"{_bound(sum(r['right_with_look_alike'] for r in inlib), len(inlib))} | "
                     f"{_bound(wrong, len(offlib))} | "
                     f"{f'{np.median(secs):.0f} / {max(secs):.0f}' if secs else '-'} |")
    lines += ["", "| seed | id | structure | force | size (x noise) | verdict | right | terms | s |",
              "|---|---|---|---|---|---|---|---|---|"]
    for r in sorted(rows, key=lambda r: (r.get("seed", 0), r["id"])):
        if "verdict" in r:
            lines.append(f"| {r.get('seed', 0)} | {r['id']} | {r['structure']} | {r['mechanism']} | "
                         f"{r['size_after_refit']:.1f} | "
                         f"{r['verdict']} | {'✓' if r['right'] else '✗'} | {', '.join(r['terms']) or '–'} | "
                         f"{r['seconds']:.0f} |")
    return "\n".join(lines) + "\n\n" + stage_shares(rows)


def seeded_rows(paths: list[Path]) -> list[dict[str, Any]]:
    """The finished rows of every file, each with its seed (a row's own, else the file name's);
    a device run again (the same seed and id) counts once, as the later file (or line) has it."""
    out: dict[tuple[int, int], dict[str, Any]] = {}
    for path in paths:
        m = re.search(r"seed(\d+)", path.name)
        for r in finished(path):
            row = {"seed": int(m.group(1)) if m else 0, **r}
            out[(row["seed"], row["id"])] = row
    return list(out.values())


def main(argv: Optional[list[str]] = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--jsonl", type=Path, nargs="+", required=True,
                    help="the rows' file (several only with --summary)")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--repeats", type=int, default=1)
    ap.add_argument("--limit", type=int)
    ap.add_argument("--only", type=int, nargs="+", metavar="ID")
    ap.add_argument("--shard", type=shard, default=(0, 1), metavar="K/N")
    ap.add_argument("--code", default="", help="the commit the diagnosis runs (kept in every row)")
    ap.add_argument("--write-only", type=Path, metavar="DIR",
                    help="write the cases into DIR and print their sizes; no diagnosis")
    ap.add_argument("--summary", action="store_true", help="print the tables of the finished cases and stop")
    a = ap.parse_args(argv)

    if a.summary:
        print(summary(seeded_rows(a.jsonl)))
        return 0
    if len(a.jsonl) > 1:
        ap.error("--jsonl takes one file when running cases (several only with --summary)")
    jsonl: Path = a.jsonl[0]
    k, n = a.shard
    done = {r["id"] for r in finished(jsonl)}
    todo = [c for c in plan(a.repeats) if c["id"] % n == k and (a.write_only or c["id"] not in done)
            and (a.only is None or c["id"] in a.only)][: a.limit]
    if a.write_only:
        for c in todo:
            row = run_case(c, a.write_only, a.seed, diagnose=False)
            print(f"{c['id']:3d} {c['structure']:7s} {c['mechanism']:24s} size {row['size_after_refit']:5.1f} "
                  f"(target {row['size_target']:.1f}) {row['extra']}", flush=True)
        return 0
    with tempfile.TemporaryDirectory() as tmp:
        for c in todo:
            row = {**run_case(c, Path(tmp), a.seed), "code": a.code, "seed": a.seed}
            append(jsonl, row)
            print(f"{c['id']:3d} {c['structure']:7s} {c['mechanism']:24s} -> {row['verdict']:<22s} "
                  f"{'right' if row['right'] else 'WRONG'} {row['seconds']:5.0f} s", flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
