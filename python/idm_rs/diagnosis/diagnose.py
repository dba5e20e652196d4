"""The diagnosis: calibrate the nominal model, locate the residual, try every catalogue effect,
rank them by information criterion and held-out prediction, and give a verdict."""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable, Optional, Sequence, Union

import numpy as np
from numpy.typing import NDArray

from ..recording import Recording, load_case
from .case_model import FIT_DT, CaseSimulator, ModelSpec, Structure
from .catalogue import CALIBRATED, CALIBRATION_RANGE, CALIBRATION_SCALE, CATALOGUE, Effect
from .fitting import FitResult, FreeParam, Objective, apply, fit, fit_progressive, set_param
from .locate import Location, locate, merge_windows
from .noise import NoiseEstimate, estimate_noise

#: BIC improvement (in chi^2 units) an effect needs to count as found: "very strong" evidence
#: on the Kass-Raftery scale
BIC_THRESHOLD = 10.0
#: an effect must beat the runner-up by this much BIC to be named alone
SEPARATION = 10.0
#: residual RMS / noise RMS below which what is left counts as noise
NOISE_RATIO_OK = 1.1
#: lag-1 autocorrelation z-score above which a residual counts as systematic
WHITENESS_Z = 5.0
#: candidates refitted over everything after the one-cycle fits of all of them
REFIT_TOP = 4


@dataclass
class Candidate:
    """One catalogue effect tried on the case."""

    effect: str
    description: str
    params: dict[str, float]  #: fitted effect parameters (catalogue names, SI)
    std: dict[str, float]  #: their 1-sigma uncertainty from the Jacobian
    calibrated: dict[str, float]  #: the nominal subset refitted alongside
    chi2: float  #: residual energy / noise variance
    n_params: int  #: fitted parameters (nominal subset + effect + offsets)
    bic: float
    delta_bic: float  #: BIC improvement over the calibrated nominal model (positive: better)
    rms_after: float  #: [m]
    heldout_rms: float  #: RMS on the held-out experiment after fitting the others [m] (NaN if not run)
    whiteness_z: float  #: lag-1 autocorrelation of the residual, as a z-score
    screened_only: bool  #: True when fitted over the first cycle only (not refined over everything)
    residuals: list[NDArray[np.float64]] = field(default_factory=list, repr=False)
    spec: Optional[ModelSpec] = field(default=None, repr=False)

    def to_dict(self) -> dict[str, Any]:
        return {
            "effect": self.effect,
            "params": self.params,
            "params_std": self.std,
            "rms_after": self.rms_after,
            "bic": self.bic,
            "delta_bic": self.delta_bic,
            "heldout_rms": None if math.isnan(self.heldout_rms) else self.heldout_rms,
            "chi2": self.chi2,
            "n_params": self.n_params,
            "whiteness_z": self.whiteness_z,
            "screened_only": self.screened_only,
            "calibrated": self.calibrated,
        }


@dataclass
class Diagnosis:
    """What `diagnose` found. `verdict` is a catalogue id, "none" or "unexplained"."""

    case: str
    verdict: str
    reason: str
    ranking: list[Candidate]
    noise: NoiseEstimate
    rms_before: float  #: nominal model, offsets fitted [m]
    rms_calibrated: float  #: after calibrating the nominal subset [m]
    rms_after: float  #: after adding the verdict's effect (= calibrated for none/unexplained) [m]
    calibrated: dict[str, float]
    calibrated_std: dict[str, float]
    locations: list[Location]  #: experiment x phase, sorted by share of excess residual energy
    windows: list[Location]  #: systematic time windows (merged), for plots
    heldout_experiment: str
    heldout_rms_calibrated: float
    whiteness_z_calibrated: float
    seconds: float
    timings: dict[str, float]  #: seconds per stage
    simulations: int
    recording: Recording = field(repr=False)
    nominal_residuals: list[NDArray[np.float64]] = field(default_factory=list, repr=False)
    calibrated_residuals: list[NDArray[np.float64]] = field(default_factory=list, repr=False)
    nominal_spec: Optional[ModelSpec] = field(default=None, repr=False)
    calibrated_spec: Optional[ModelSpec] = field(default=None, repr=False)
    simulator: Optional[CaseSimulator] = field(default=None, repr=False)

    @property
    def best(self) -> Optional[Candidate]:
        return self.ranking[0] if self.ranking else None

    def to_dict(self) -> dict[str, Any]:
        return {
            "case": self.case,
            "verdict": self.verdict,
            "reason": self.reason,
            "ranking": [c.to_dict() for c in self.ranking],
            "rms_before": self.rms_before,
            "rms_calibrated": self.rms_calibrated,
            "rms_after": self.rms_after,
            "noise_rms": self.noise.sigma,
            "noise": self.noise.__dict__,
            "calibrated": self.calibrated,
            "calibrated_std": self.calibrated_std,
            "locations": [l.to_dict() for l in self.locations],
            "systematic_windows": [w.to_dict() for w in self.windows],
            "heldout_experiment": self.heldout_experiment,
            "heldout_rms_calibrated": self.heldout_rms_calibrated,
            "whiteness_z_calibrated": self.whiteness_z_calibrated,
            "seconds": self.seconds,
            "timings": self.timings,
            "simulations": self.simulations,
        }

    def report(self) -> str:
        from .report import text_report

        return text_report(self)

    def plot(self, directory: Union[str, Path]) -> list[Path]:
        from .plots import plot_diagnosis

        return plot_diagnosis(self, Path(directory))


def whiteness_z(residuals: Sequence[NDArray[np.float64]]) -> float:
    """Lag-1 autocorrelation of the residuals (per file, pooled) times sqrt(n): about N(0, 1) for
    white noise, large for a smooth systematic residual — without needing the noise level."""
    num = den = 0.0
    n = 0
    for r in residuals:
        r = r - r.mean()
        num += float(np.dot(r[1:], r[:-1]))
        den += float(np.dot(r, r))
        n += r.size
    return num / den * math.sqrt(n) if den > 0 else 0.0


def _heldout_index(rec: Recording) -> int:
    """The experiment held out: the largest one of a direction that has at least two, so the
    rest still show both directions."""
    by_dir: dict[str, list[int]] = {}
    for i, e in enumerate(rec.experiments):
        by_dir.setdefault(e.direction, []).append(i)
    pool = [i for idx in by_dir.values() if len(idx) >= 2 for i in idx] or list(range(len(rec.experiments)))
    return max(pool, key=lambda i: rec.experiments[i].n_samples)


def _calibration_params(p: dict) -> list[FreeParam]:
    lo, hi = CALIBRATION_RANGE
    return [FreeParam(n, p[n], lo * p[n], hi * p[n], CALIBRATION_SCALE * p[n], set_param(n)) for n in CALIBRATED]


def diagnose(case: Union[str, Path, Recording], *, progress: bool = True, dt: float = FIT_DT,
             threads: Optional[int] = None, refit_top: int = REFIT_TOP) -> Diagnosis:
    """Diagnose a recorded case (a directory in the `idm-recording/1` format, or a Recording)."""
    t_start = time.perf_counter()
    rec = case if isinstance(case, Recording) else load_case(case)
    bar = _bar(progress, rec.name)
    noise = estimate_noise(rec)
    sigma = noise.sigma
    sim = CaseSimulator(rec, dt=dt, threads=threads)
    obj = Objective(rec, sim, sigma)
    n = obj.n
    n_off = len(rec.experiments)
    ln_n = math.log(n)
    tick = bar.update if bar is not None else None

    # the nominal model as given; the normal force follows the masses when meta's value does
    nom = rec.nominal
    p0 = nom.params.to_dict(resolved=False)
    derived = (p0["m1"] + p0["m2"] + nom.params.pe_mass) * 9.81
    if p0.get("normal_force") is not None and abs(p0["normal_force"] / derived - 1.0) < 1e-5:
        p0["normal_force"] = None
    structure0 = Structure(nom.model, nom.n_elements, nom.piezo_hysteresis)
    spec0 = ModelSpec(structure0, p0, {})
    pred0 = sim.predict([spec0])[0]
    res_nominal, _ = obj.profiled(pred0)
    chi2_nominal = float(sum(np.sum(r * r) for r in res_nominal)) / sigma**2

    # 1. calibrate the plausibly-off nominal parameters
    cal_free = _calibration_params(p0)
    timings: dict[str, float] = {}
    clock = time.perf_counter()

    def lap(name: str) -> None:
        nonlocal clock
        now = time.perf_counter()
        timings[name] = timings.get(name, 0.0) + now - clock
        clock = now

    # first over one drive cycle, where the misfit is a smooth function of the parameters;
    # then over two cycles and everything, each stage from the previous optimum
    obj1 = obj.with_cycles(1)
    cal1 = fit(obj1, spec0, cal_free, max_nfev=20, progress=tick)
    cal1_at = [f.at(cal1.values[f.name]) for f in cal_free]
    cal = fit_progressive(obj, spec0, cal1_at, horizons=(2, None), max_nfev=(12, 12), progress=tick)
    lap("calibration")
    k_cal = len(cal_free) + n_off
    bic_cal = cal.chi2 + k_cal * ln_n
    wz_cal = whiteness_z(cal.residuals)
    locations, windows = locate(rec, cal.residuals, sigma)
    spans = merge_windows(windows, sigma)
    # held-out split: fit on the others, predict this one
    ho = _heldout_index(rec)
    train = [i for i in range(len(rec.experiments)) if i != ho]
    obj_train = Objective(rec, sim, sigma, train)

    def heldout_rms(spec: ModelSpec, free: Sequence[FreeParam]) -> float:
        # refit on the training experiments from the full-data solution, then predict
        start = [f.at(f.value(0.0)) for f in free]
        r = fit(obj_train, spec, start, max_nfev=8, progress=tick)
        pred = sim.predict([r.spec])[0]
        d = rec.experiments[ho].x - pred[ho]
        d = d - d.mean()
        return float(math.sqrt(np.mean(d * d)))

    cal_at = [f.at(cal.values[f.name]) for f in cal_free]
    ho_cal = heldout_rms(cal.spec, cal_at)
    lap("held-out")

    # 2. every applicable effect fitted over the first cycle, where the misfit is smooth (a
    # linearisation about the calibration is not enough: when an effect is large, the
    # nominal-only calibration compensates it with far-off parameters)
    effects = [e for e in CATALOGUE if e.applies(structure0, p0)]
    n1 = obj1.n
    first: list[tuple[Effect, FitResult, list[FreeParam], ModelSpec]] = []
    for eff in effects:
        base = ModelSpec(eff.structure(structure0), dict(cal1.spec.params), dict(cal1.spec.effects))
        grids = [ep.starts for ep in eff.params]
        combos = [tuple(s) for s in np.array(np.meshgrid(*grids, indexing="ij")).reshape(len(grids), -1).T] if grids else [()]
        starts = [[ep.free(v) for ep, v in zip(eff.params, c)] for c in combos]
        if len(starts) > 1:  # the best multi-start value, judged over the first cycle
            preds = obj1.predict([apply(base, cal1_at + st, np.zeros(len(cal1_at) + len(st))) for st in starts])
            st = starts[int(np.argmin([float(np.sum(obj1.vector(p) ** 2)) for p in preds]))]
        else:
            st = starts[0]
        free = cal1_at + st
        r1 = fit(obj1, base, free, max_nfev=15, progress=tick)
        first.append((eff, r1, free, base))
    lap("one-cycle fits")
    # ... and screened about the full-horizon calibration (linearised): effects that grow over
    # the cycles (a ground spring, drift, creep) can hide in the first one
    screen_all = {s["effect"].id: s for s in _screen(obj, cal, cal_at, effects, sigma)}
    bic1 = {eff.id: r1.chi2 + len(fr) * math.log(n1) for eff, r1, fr, _ in first}
    rank1 = {k: i for i, k in enumerate(sorted(bic1, key=bic1.get))}
    rank_all = {k: i for i, k in enumerate(sorted(screen_all, key=lambda k: -screen_all[k]["delta_chi2"]))}
    first.sort(key=lambda x: (min(rank1[x[0].id], rank_all[x[0].id]), rank1[x[0].id]))
    lap("screening")

    # 3. the leading effects refitted over two cycles and everything, from their one-cycle fit
    # or from the screened estimate, whichever fits the first two cycles better
    obj2 = obj.with_cycles(2)
    ranking: list[Candidate] = []
    for i, (eff, r1, free, base) in enumerate(first):
        k = len(cal_free) + len(eff.params) + n_off
        eff_names = [ep.name for ep in eff.params]
        start = [f.at(r1.values[f.name]) for f in free]
        if i < refit_top:
            est = screen_all[eff.id]["estimate"]
            alt = cal1_at + [ep.free(v) for ep, v in zip(eff.params, est)]
            chis = [obj2.chi2(apply(base, s, np.zeros(len(s)))) for s in (start, alt)]
            start = (start, alt)[int(np.argmin(chis))]
            r = fit_progressive(obj, base, start, horizons=(2, None), max_nfev=(12, 10), progress=tick)
            full = True
        else:  # reported with its one-cycle parameters, evaluated over everything
            spec = apply(base, start, np.zeros(len(start)))
            res, _ = obj.profiled(obj.predict([spec])[0])
            chi2 = float(sum(np.sum(x * x) for x in res)) / sigma**2
            r = FitResult(r1.values, r1.std, chi2, n, res, [], spec, 0, True, "one-cycle fit only")
            full = False
        cand = Candidate(
            eff.id, eff.description, _report_params(eff, r), {n_: r.std[n_] for n_ in eff_names},
            {n_: r.values[n_] for n_ in CALIBRATED}, r.chi2, k, r.chi2 + k * ln_n,
            bic_cal - (r.chi2 + k * ln_n), r.rms, math.nan, whiteness_z(r.residuals), not full,
            r.residuals, r.spec)
        cand._free = [f.at(r.values[f.name]) for f in free]  # type: ignore[attr-defined]
        cand._base = base  # type: ignore[attr-defined]
        ranking.append(cand)
    lap("refits")
    # candidates refitted over everything first, then those fitted over the first cycle only
    ranking.sort(key=lambda c: (c.screened_only, -c.delta_bic))
    # held-out prediction for the leading refitted candidates
    for c in [c for c in ranking if not c.screened_only][:2]:
        c.heldout_rms = heldout_rms(c._base, c._free)  # type: ignore[attr-defined]

    lap("held-out")
    verdict, reason, rms_after = _verdict(ranking, cal, noise, wz_cal, ho_cal)
    if bar is not None:
        bar.close()
    return Diagnosis(
        case=rec.name, verdict=verdict, reason=reason, ranking=ranking, noise=noise,
        rms_before=sigma * math.sqrt(chi2_nominal / n), rms_calibrated=cal.rms, rms_after=rms_after,
        calibrated=cal.values, calibrated_std=cal.std, locations=locations, windows=spans,
        heldout_experiment=rec.experiments[ho].name, heldout_rms_calibrated=ho_cal, whiteness_z_calibrated=wz_cal,
        seconds=time.perf_counter() - t_start, timings=timings, simulations=sim.evaluations, recording=rec,
        nominal_residuals=res_nominal, calibrated_residuals=cal.residuals, nominal_spec=spec0,
        calibrated_spec=cal.spec, simulator=sim,
    )


def _report_params(eff: Effect, r: FitResult) -> dict[str, float]:
    """Effect parameters under their catalogue names (mu_s rather than the fitted excess)."""
    vals = {ep.name: r.values[ep.name] for ep in eff.params}
    if eff.id == "stribeck":
        mu_k = r.values["mu_k"]
        return {"mu_s": mu_k * (1.0 + vals["mu_s_excess"]), "mu_k": mu_k}
    if eff.id == "pe_mass":
        return {}
    return vals


def _screen(obj: Objective, cal: FitResult, cal_at: list[FreeParam], effects: Sequence[Effect],
            sigma: float) -> list[dict]:
    """Rao-score screening: the chi^2 drop a Gauss-Newton step would give when each effect's
    parameters join the calibrated ones, from one batch of Jacobian columns. Multi-start values
    of nonlinear parameters are compared by their own chi^2 first."""
    from scipy.optimize import lsq_linear

    r0 = np.concatenate(cal.residuals) / sigma
    h = 1e-3
    specs: list[ModelSpec] = []
    # nominal columns
    for j in range(len(cal_at)):
        u = np.zeros(len(cal_at))
        u[j] = h
        specs.append(apply(cal.spec, cal_at, u))
    plan = []
    for eff in effects:
        base = ModelSpec(eff.structure(cal.spec.structure), dict(cal.spec.params), dict(cal.spec.effects))
        grids = [ep.starts for ep in eff.params]
        starts = [tuple(s) for s in np.array(np.meshgrid(*grids, indexing="ij")).reshape(len(grids), -1).T] if grids else [()]
        entry = {"effect": eff, "base": base, "starts": starts, "start_idx": len(specs)}
        for st in starts:  # the effect at each start
            free = [ep.free(v) for ep, v in zip(eff.params, st)]
            specs.append(apply(base, free, np.zeros(len(free))))
        plan.append(entry)
    preds = obj.predict(specs)
    Jn = np.stack([(obj.vector(preds[j]) - r0) / h for j in range(len(cal_at))], axis=1)
    # second pass: derivatives of the effect parameters at the best start
    specs2, plan2 = [], []
    for entry in plan:
        eff = entry["effect"]
        chis = [float(np.sum(obj.vector(preds[entry["start_idx"] + i]) ** 2)) for i in range(len(entry["starts"]))]
        best = int(np.argmin(chis))
        entry["start"] = entry["starts"][best]
        entry["r_start"] = obj.vector(preds[entry["start_idx"] + best])
        free = [ep.free(v) for ep, v in zip(eff.params, entry["start"])]
        entry["free"] = free
        idx = len(specs2)
        for j, f in enumerate(free):
            lo, hi = f.u_bounds()
            u = np.zeros(len(free))
            u[j] = h if h <= hi else -h
            specs2.append(apply(entry["base"], free, u))
        entry["cols"] = (idx, [(h if h <= f.u_bounds()[1] else -h) for f in free])
        plan2.append(entry)
    preds2 = obj.predict(specs2) if specs2 else []
    out = []
    # baseline: what a further step in the nominal parameters alone would gain (the calibration
    # stops near, not at, its optimum); each effect is credited only with what it adds
    lo_n = np.array([f.u_bounds()[0] for f in cal_at])
    hi_n = np.array([f.u_bounds()[1] for f in cal_at])
    du_n = lsq_linear(Jn, -r0, bounds=(np.minimum(lo_n, -1e-12), np.maximum(hi_n, 1e-12))).x
    chi2_cal = float(np.sum((r0 + Jn @ du_n) ** 2))
    for entry in plan2:
        idx, steps = entry["cols"]
        rs = entry["r_start"]
        Je = [(obj.vector(preds2[idx + j]) - rs) / s for j, s in enumerate(steps)]
        A = np.concatenate([Jn, np.stack(Je, axis=1)], axis=1) if Je else Jn
        # bounded Gauss-Newton step from the start point: chi2 at the linearised optimum
        bounds = [f.u_bounds() for f in cal_at] + [f.u_bounds() for f in entry["free"]]
        lo = np.array([b[0] for b in bounds])
        hi = np.array([b[1] for b in bounds])
        du = lsq_linear(A, -rs, bounds=(np.minimum(lo, -1e-12), np.maximum(hi, 1e-12))).x
        chi2_lin = float(np.sum((rs + A @ du) ** 2))
        est = [f.value(float(np.clip(d, *f.u_bounds()))) for f, d in zip(entry["free"], du[Jn.shape[1]:])]
        out.append({"effect": entry["effect"], "start": entry["start"], "delta_chi2": chi2_cal - chi2_lin,
                    "estimate": est, "mu_k": cal.values["mu_k"]})
    return out


def _verdict(ranking: list[Candidate], cal: FitResult, noise: NoiseEstimate, wz_cal: float,
             ho_cal: float) -> tuple[str, str, float]:
    sigma = noise.sigma
    cal_ratio = cal.rms / sigma
    cal_is_noise = cal_ratio <= NOISE_RATIO_OK and wz_cal <= WHITENESS_Z
    best = ranking[0] if ranking else None
    second = ranking[1] if len(ranking) > 1 else None
    if best is None or best.delta_bic < BIC_THRESHOLD or best.screened_only:
        if cal_is_noise:
            return ("none", f"after calibration the residual is noise (RMS {cal_ratio:.2f} x noise, whiteness "
                    f"z = {wz_cal:.1f}) and no effect improves BIC by {BIC_THRESHOLD:g}", cal.rms)
        return ("unexplained", f"a systematic residual remains after calibration (RMS {cal_ratio:.2f} x noise, "
                f"whiteness z = {wz_cal:.1f}) and no catalogue effect reduces it", cal.rms)
    ratio = best.rms_after / sigma
    explained = ratio <= NOISE_RATIO_OK and best.whiteness_z <= WHITENESS_Z
    heldout_ok = math.isnan(best.heldout_rms) or best.heldout_rms <= ho_cal * 1.02
    if not explained:
        return ("unexplained", f"the best effect ({best.effect}, ΔBIC {best.delta_bic:.0f}) leaves a systematic "
                f"residual (RMS {ratio:.2f} x noise, whiteness z = {best.whiteness_z:.1f})", cal.rms)
    if second is not None and best.delta_bic - second.delta_bic < SEPARATION:
        note = f"; runner-up {second.effect} is close (ΔBIC {second.delta_bic:.0f})"
    else:
        note = ""
    if not heldout_ok:
        note += "; held-out prediction does not improve"
    return (best.effect, f"{best.effect} improves BIC by {best.delta_bic:.0f} and leaves noise (RMS {ratio:.2f} x "
            f"noise){note}", best.rms_after)


def _bar(show: bool, name: str) -> Any:
    if not show:
        return None
    from tqdm.auto import tqdm

    return tqdm(desc=f"diagnosing {name}", unit="eval")
