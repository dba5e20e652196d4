"""The diagnosis's datasheet: a confusion matrix (true effect x verdict) measured on simulated
recordings, and the false-alarm rate on healthy devices.

    python benches/bench_confusion.py --jsonl confusion.jsonl --out benches/confusion.md \
        --figure docs/img/confusion_matrix.png [--healthy 100] [--limit N] [--shard K/N]

Every catalogue effect at two sizes — its signal left after a (linearised) refit of the nominal
subset about 3x and 8x the noise RMS — on two devices (LPS and DPS n = 4, neither with piezo
hysteresis in its nominal model), the nominal values in meta.json mis-set by 5-15 % (1-3 of the
calibrated parameters), plus `--healthy` devices that lack nothing (as in
``bench_false_alarm.py``). Each case is written with ``idm_rs.io.synthetic.make_case`` (RK4 at
dt = 2e-8 s, white noise of 1-2 nm RMS, 0.25 nm quantisation) and diagnosed. The size is tuned
per case before writing it: the effect's reading minus the true null model's, its per-segment
offsets removed and projected off the exact Jacobian of the calibrated subset (what a refit of
those parameters would absorb, to first order), has the target RMS in noise units. ``pe_mass``
(a structure, no magnitude) has one size: whatever the bar's mass gives.

One line of JSON per finished case goes to ``--jsonl`` as it finishes; cases already there are
skipped, so the run resumes across sessions (the cases are drawn from ``--seed`` in a fixed
order, so a resumed run diagnoses the same ones). Run it in the background from a separate
install (a wheel in its own venv); a case takes about as long as one diagnosis. ``--shard 0/2``
and ``--shard 1/2`` side by side split the cases between two processes writing one JSONL (each
case's seconds are then those of a diagnosis sharing the machine).
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

sys.path.insert(0, str(Path(__file__).resolve().parent))
from bench_false_alarm import EXPERIMENTS, null_case
from bench_rows import append, finished, shard
from idm_rs.diagnosis.thresholds import CALIBRATED

#: the two sizes: RMS of the effect's signal after a linearised refit, in noise units
SIZES = {"small": 3.0, "large": 8.0}
#: the two devices every effect is put on
DEVICES = ("lps", "dps")
#: the magnitude parameter of each effect, the other parameters' values, and a first guess
MAGNITUDE: dict[str, tuple[str, dict[str, float], float]] = {
    "piezo_hysteresis": ("hyst_alpha", {}, 0.003),
    "stribeck": ("mu_s_excess", {}, 0.02),
    "incline": ("theta_rad", {}, -3e-4),
    "spring_to_ground": ("k_ground", {}, 3e3),
    "amplifier_lowpass": ("tau_amp", {}, 3e-6),
    "piezo_creep": ("kappa", {"tau_creep": 0.005}, 0.01),
    "weight_friction": ("c_weight", {}, 1.0),
    "friction_asymmetry": ("eps", {}, 2e-3),
    "sensor_lowpass": ("tau_sensor", {}, 5e-6),
    "thermal_drift": ("drift_rate", {}, -3e-7),
}


def plan(healthy: int) -> list[dict[str, Any]]:
    """Every case, in the order run: the large effects first, then the small, healthy devices
    interleaved (one after every two effect cases, the rest at the end)."""
    from idm_rs.diagnosis.catalogue import CATALOGUE

    effects = []
    for size in ("large", "small"):
        for device in DEVICES:
            for e in CATALOGUE:
                if e.id == "pe_mass" and (device != "lps" or size != "large"):
                    continue  # a structure: one size, and only an LPS nominal can lack it
                effects.append({"kind": "effect", "effect": e.id, "size": size, "device": device})
    out, h = [], 0
    for i, c in enumerate(effects):
        out.append(c)
        if i % 2 == 1 and h < healthy:
            out.append({"kind": "healthy", "index": h})
            h += 1
    out += [{"kind": "healthy", "index": k} for k in range(h, healthy)]
    for i, c in enumerate(out):
        c["id"] = i
    return out


def _misset(true: Any, rng: np.random.Generator) -> tuple[Any, dict[str, float]]:
    names = rng.choice(CALIBRATED, size=int(rng.integers(1, 4)), replace=False)
    misset = {str(n): float(rng.choice([-1, 1]) * rng.uniform(0.05, 0.15)) for n in names}
    given = {n: getattr(true, n) * (1 + f) for n, f in misset.items()}
    return given, misset


def _true_device(effect: str, magnitude: float, device: str) -> tuple[Any, Any, str, str]:
    """(true Params, Effects, true model, nominal model) of an effect case."""
    import idm_rs

    p = idm_rs.Params()
    name, others, _ = MAGNITUDE.get(effect, ("", {}, 0.0))
    fields: dict[str, float] = {}
    model, nominal_model = device, device
    if effect == "pe_mass":
        model, nominal_model = "dps", "lps"
    elif effect == "piezo_hysteresis":
        p = p.replace(hyst_alpha=magnitude)
    elif effect == "stribeck":
        p = p.replace(mu_s=p.mu_k * (1.0 + magnitude))
    else:
        fields = {name: magnitude, **others}
    return p, idm_rs.Effects(**fields), model, nominal_model


def _size(effect: str, magnitude: float, device: str, sim: Any, obj: Any, Q: np.ndarray) -> float:
    """RMS [noise units] of the effect's signal left after a linearised refit of the
    calibrated subset."""
    from idm_rs.diagnosis.case_model import ModelSpec, Structure

    p, eff, model, nominal_model = _true_device(effect, magnitude, device)
    null_p, _, _, _ = _true_device(effect, 0.0 if effect != "piezo_hysteresis" else 0.0, device)
    hyst = effect == "piezo_hysteresis"
    s_eff = ModelSpec(Structure(model, 4 if model == "dps" else 1, hyst), _spec_params(p), dataclasses.asdict(eff))
    s_null = ModelSpec(Structure(nominal_model, 4 if nominal_model == "dps" else 1, False),
                       _spec_params(null_p if effect != "stribeck" else null_p.replace(mu_s=null_p.mu_k)), {})
    a, b = obj.predict([s_eff, s_null])
    d = obj.vector(a) - obj.vector(b)
    d = d - Q @ (Q.T @ d)
    return float(np.linalg.norm(d) / math.sqrt(d.size))


def _spec_params(p: Any) -> dict[str, Any]:
    return p.to_dict(resolved=False)


def _tuned(effect: str, device: str, target: float, noise: float) -> tuple[float, float]:
    """(magnitude, size reached): the effect's magnitude whose signal, after a linearised refit of
    the calibrated subset, has RMS `target` x `noise` on the EXPERIMENTS of `device` (secant in
    log space, within half its fit bounds); (nan, nan) for pe_mass (a structure)."""
    from idm_rs.diagnosis.case_model import CaseSimulator, ModelSpec, Structure
    from idm_rs.diagnosis.catalogue import by_id
    from idm_rs.diagnosis.fitting import FreeParam, Objective, set_param
    from idm_rs.diagnosis.thresholds import CALIBRATION_SCALE
    from idm_rs.io.recording import load_case
    from idm_rs.io.synthetic import make_case

    if effect == "pe_mass":
        return math.nan, math.nan
    name, _, guess = MAGNITUDE[effect]
    # a noise-free null recording of the same experiments, to simulate sizes on
    with tempfile.TemporaryDirectory() as tmp:
        null_p, _, model, _ = _true_device(effect, 0.0, device)
        if effect == "stribeck":
            null_p = null_p.replace(mu_s=null_p.mu_k)
        make_case(Path(tmp) / "n", nominal_params=null_p.replace(normal_force=null_p.effective_normal_force),
                  model=model, experiments=EXPERIMENTS, noise_rms=0.0, resolution=0.0, seed=0, dt=2e-7)
        rec = load_case(Path(tmp) / "n")
    sim = CaseSimulator(rec)
    obj = Objective(rec, sim, noise)
    spec = ModelSpec(Structure(model, 4 if model == "dps" else 1, False), _spec_params(null_p), {})
    free = [FreeParam(n, float(getattr(null_p, n)), 0.6 * getattr(null_p, n), 1.5 * getattr(null_p, n),
                      CALIBRATION_SCALE * getattr(null_p, n), set_param(n)) for n in CALIBRATED]
    _, J, _ = obj.jacobian(spec, free, np.zeros(len(free)))
    Q, _ = np.linalg.qr(J)
    ep = next(p for p in by_id(effect).params if p.name == name)
    # within the diagnosis's fit bounds (an effect it could not fit says nothing), and within
    # half of them: a size that needs more is reported at that magnitude, not reached
    cap = 0.5 * max(abs(ep.lower), abs(ep.upper))
    magnitude, size = guess, math.nan
    for _ in range(6):  # secant in log space on size(magnitude) = target
        size = _size(effect, magnitude, device, sim, obj, Q)
        if not math.isfinite(size) or size <= 0 or abs(size / target - 1) < 0.05:
            break
        new = magnitude * min(max(target / size, 0.1), 10.0)
        new = math.copysign(min(abs(new), cap), new)
        if new == magnitude:
            break  # capped: the size stays below the target
        magnitude = new
        size = math.nan
    if not math.isfinite(size):
        size = _size(effect, magnitude, device, sim, obj, Q)
    return magnitude, size


def _nominal_of(effects: list[str], p: Any, true0: Any, given: dict[str, float]) -> Any:
    """meta.json's parameters of a device whose true parameters are `p` with `effects`: the
    effect's own parameter back at the nominal model's value (no Stribeck peak, the Table 1
    hysteresis), then the mis-set values `given`."""
    nominal = p
    if "stribeck" in effects:
        nominal = nominal.replace(mu_s=nominal.mu_k)
    if "piezo_hysteresis" in effects:
        nominal = nominal.replace(hyst_alpha=true0.hyst_alpha)
    nominal = nominal.replace(**{k: v for k, v in given.items()})
    if "mu_k" in given and "stribeck" not in effects:
        nominal = nominal.replace(mu_k=min(given["mu_k"], 0.99 * p.mu_s))
    if "stribeck" in effects and "mu_k" in given:
        nominal = nominal.replace(mu_s=nominal.mu_k)
    return nominal


def effect_case(directory: Path, c: dict[str, Any], rng: np.random.Generator,
                sensor: Any = None, resolution: Any = None) -> dict[str, Any]:
    """Write one effect case with its size tuned; returns what was set. `sensor`: a function of
    the drawn white-noise RMS giving the reading's ``SensorNoise`` (None: white noise);
    `resolution`: one of that RMS giving the reading's resolution [m] (None: make_case's)."""
    import idm_rs
    from idm_rs.io.synthetic import make_case

    effect, device = c["effect"], c["device"]
    noise = float(rng.uniform(1.0e-9, 2.0e-9))
    seed = int(rng.integers(0, 2**31))
    true0 = idm_rs.Params()
    given, misset = _misset(true0, rng)
    name = MAGNITUDE.get(effect, ("", {}, 0.0))[0]
    magnitude, size = _tuned(effect, device, SIZES[c["size"]], noise)
    p, eff, model, nominal_model = _true_device(effect, magnitude, device)
    nominal = _nominal_of([effect], p, true0, given)
    true = p.replace(normal_force=p.effective_normal_force)
    make_case(directory, nominal_params=nominal.replace(normal_force=true.normal_force), true_params=true,
              model=nominal_model, n_elements=4, piezo_hysteresis=False, true_model=model,
              true_piezo_hysteresis=effect == "piezo_hysteresis", effects=eff, experiments=EXPERIMENTS,
              noise_rms=noise, seed=seed, dt=2e-8, noise=sensor(noise) if sensor is not None else None,
              **({"resolution": resolution(noise)} if resolution is not None else {}))
    return {"misset": misset, "magnitude": {name: magnitude} if name else {}, "size_after_refit": size,
            "noise_rms": noise}


def _key_error(d: Any, c: dict[str, Any], info: dict[str, Any]) -> Optional[float]:
    if d.verdict != c.get("effect") or not info.get("magnitude"):
        return None
    cand = next((x for x in d.ranking if x.effect == d.verdict), None)
    (name, truth), = info["magnitude"].items()
    if cand is None:
        return None
    if name == "mu_s_excess":
        v = cand.params.get("mu_s", math.nan) / cand.params.get("mu_k", math.nan) - 1.0
    else:
        v = cand.params.get(name, math.nan)
    return float(v / truth - 1.0)


def diagnosed(directory: Path) -> tuple[Any, float]:
    """(the Diagnosis of the case in `directory`, its seconds), warnings silenced."""
    import idm_rs

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        t0 = time.perf_counter()
        d = idm_rs.diagnose(directory, progress=False)
        return d, time.perf_counter() - t0


def run_case(c: dict[str, Any], tmp: Path, seed: int) -> dict[str, Any]:
    rng = np.random.default_rng([seed, c["id"]])
    directory = tmp / f"case{c['id']:03d}"
    if c["kind"] == "healthy":
        info = null_case(directory, rng)
        truth = "none"
    else:
        info = effect_case(directory, c, rng)
        truth = c["effect"]
    d, seconds = diagnosed(directory)
    return {**c, **info, "truth": truth, "verdict": d.verdict, "right": d.verdict == truth, "seconds": seconds,
            "calibrated_over_noise": d.rms_calibrated / d.noise.sigma, "after_over_noise": d.rms_after / d.noise.sigma,
            "key_error": _key_error(d, c, info), "alternatives": [a.effect for a in d.alternatives],
            "reason": d.reason, **_margin(d),
            # discovery beyond the catalogue: whether it ran (the catalogue left a systematic
            # residual) and whether it named a term (a "discovered" verdict)
            "discovery_ran": d.discovery is not None, "discovered": d.verdict == "discovered",
            "discovery_seconds": d.discovery.seconds if d.discovery is not None else 0.0,
            "timings": dict(d.timings)}


def _margin(d: Any) -> dict[str, Any]:
    """The strongest competitor of the verdict among the refined candidates: on a healthy device,
    how far the best effect came from being named (its ΔBIC against BIC_THRESHOLD, its
    likelihood-ratio statistic), so the threshold's margin is measured, not only the count."""
    fitted = [x for x in d.ranking if not x.screened_only and not x.at_null and x.effect != d.verdict]
    if not fitted:
        return {"best_other": None, "best_other_delta_bic": None, "best_other_lr_chi2": None}
    best = max(fitted, key=lambda x: x.delta_bic)
    lr = best.lr_chi2 if math.isfinite(best.lr_chi2) else None
    return {"best_other": best.effect, "best_other_delta_bic": float(best.delta_bic), "best_other_lr_chi2": lr}


def table(rows: list[dict[str, Any]]) -> str:
    from scipy.stats import beta

    verdicts = sorted({r["verdict"] for r in rows} | {"none", "discovered", "unexplained", "not_converged"})
    truths = sorted({r["truth"] for r in rows}, key=lambda t: (t == "none", t))
    lines = []
    for size in ("large", "small", None):
        sel = [r for r in rows if (r.get("size") == size if size else r["truth"] == "none")]
        if not sel:
            continue
        title = f"effects at the {size} size ({SIZES[size]:g}x noise after refit)" if size else "healthy devices"
        right = sum(r["right"] for r in sel)
        lines += [f"**{title}**: {right} of {len(sel)} right ({100 * right / len(sel):.0f} %)", "",
                  "| true \\ verdict | " + " | ".join(verdicts) + " |", "|---|" + "---|" * len(verdicts)]
        for t in truths:
            tr = [r for r in sel if r["truth"] == t]
            if tr:
                counts = (str(sum(r["verdict"] == v for r in tr)) or "" for v in verdicts)
                lines.append(f"| {t} | " + " | ".join(counts) + " |")
        reached = []
        for t in truths:
            sizes = [r.get("size_after_refit") for r in sel if r["truth"] == t]
            sizes = [x for x in sizes if isinstance(x, float) and math.isfinite(x)]
            if t != "none" and sizes:
                reached.append(t + " " + ", ".join("%.1f" % x for x in sizes))
        if reached:
            lines += ["", "sizes reached (the signal's RMS after a linearised refit, x noise; below the target where "
                          "the magnitude hit half its fit bound or the signal saturates): " + "; ".join(reached)]
        lines.append("")
    healthy = [r for r in rows if r["truth"] == "none"]
    alarms = sum(r["verdict"] not in ("none", "unexplained", "not_converged") for r in healthy)
    n = len(healthy)
    upper = float(beta.ppf(0.95, alarms + 1, n - alarms)) if n else math.nan
    secs = [r["seconds"] for r in rows]
    lines.append(f"false alarms (an effect named on a healthy device): {alarms} of {n} (95 % upper bound of the "
                 f"rate {upper:.3f}); time per case: median {np.median(secs):.0f} s, max {max(secs):.0f} s")
    ran = [r for r in rows if r.get("discovery_ran")]
    lines.append(f"discovery (beyond the catalogue) ran on {len(ran)} of {len(rows)} cases and named a term on "
                 f"{sum(bool(r.get('discovered')) for r in rows)} (on a healthy device "
                 f"{sum(bool(r.get('discovered')) for r in healthy)}, on a catalogue case "
                 f"{sum(bool(r.get('discovered')) for r in rows if r['truth'] != 'none')})"
                 + (f"; its time: max {max(r.get('discovery_seconds', 0.0) for r in ran):.0f} s" if ran else ""))
    margins = [r["best_other_delta_bic"] for r in healthy if r.get("best_other_delta_bic") is not None]
    if margins:
        from idm_rs.diagnosis.thresholds import BIC_THRESHOLD

        top = max((r for r in healthy if r.get("best_other_delta_bic") is not None),
                  key=lambda r: r["best_other_delta_bic"])
        lines.append(f"\nthe threshold's margin on healthy devices: the best refined effect's ΔBIC was "
                     f"median {np.median(margins):.1f}, max {max(margins):.1f} ({top['best_other']}, case "
                     f"{top['id']}) against BIC_THRESHOLD {BIC_THRESHOLD:g}; {len(margins)} of {n} had a refined "
                     f"candidate")
    elif healthy:
        lines.append(f"\nthe threshold's margin on healthy devices: none of the {n} got as far as a refined candidate "
                     f"(every effect was screened out or ended at its 'no effect' value)")
    lines.append("")
    return "\n".join(lines) + "\n"


def figure(rows: list[dict[str, Any]], path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    verdicts = sorted({r["verdict"] for r in rows} | {"none", "discovered", "unexplained", "not_converged"})
    truths = sorted({r["truth"] for r in rows}, key=lambda t: (t == "none", t))
    M = np.array([[sum(r["verdict"] == v for r in rows if r["truth"] == t) for v in verdicts] for t in truths], float)
    frac = M / np.maximum(M.sum(axis=1, keepdims=True), 1)
    fig, ax = plt.subplots(figsize=(1.0 + 0.55 * len(verdicts), 1.0 + 0.45 * len(truths)))
    ax.imshow(frac, cmap="Blues", vmin=0, vmax=1)
    for i in range(len(truths)):
        for j in range(len(verdicts)):
            if M[i, j]:
                ax.text(j, i, f"{int(M[i, j])}", ha="center", va="center", fontsize=8,
                        color="white" if frac[i, j] > 0.6 else "black")
    ax.set_xticks(range(len(verdicts)), verdicts, rotation=60, ha="right", fontsize=8)
    ax.set_yticks(range(len(truths)), truths, fontsize=8)
    ax.set_xlabel("verdict")
    ax.set_ylabel("true effect")
    ax.set_title(f"diagnosis confusion matrix ({len(rows)} simulated recordings, both sizes)", fontsize=9)
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=130)
    plt.close(fig)


def main(argv: Optional[list[str]] = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--healthy", type=int, default=100)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--limit", type=int, help="run at most this many new cases, then write the table")
    ap.add_argument("--shard", type=shard, default=(0, 1), metavar="K/N",
                    help="run only the cases whose id is K modulo N (N processes side by side, one JSONL)")
    ap.add_argument("--only", type=int, nargs="+", metavar="ID",
                    help="run only these case ids (e.g. a quiet re-run of the slowest: --only 24 25 39 54)")
    ap.add_argument("--jsonl", type=Path, required=True)
    ap.add_argument("--out", type=Path)
    ap.add_argument("--figure", type=Path)
    a = ap.parse_args(argv)
    k, n = a.shard
    done = {r["id"] for r in finished(a.jsonl)}
    todo = [c for c in plan(a.healthy) if c["id"] not in done and c["id"] % n == k
            and (a.only is None or c["id"] in a.only)][: a.limit]
    with tempfile.TemporaryDirectory() as tmp:
        for c in todo:
            row = run_case(c, Path(tmp), a.seed)
            print(json.dumps(row), flush=True)
            append(a.jsonl, row)
    rows = finished(a.jsonl)
    md = table(rows)
    print(md)
    if a.out:
        a.out.write_text(md)
    if a.figure and rows:
        figure(rows, a.figure)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
