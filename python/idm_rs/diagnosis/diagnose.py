"""The diagnosis: calibrate the nominal model, locate the residual, try every catalogue effect,
rank them by information criterion and held-out prediction, and give a verdict.

:func:`diagnose` runs named stages in order: the nominal model as given, calibration, the
held-out split, one-cycle fits of every applicable effect, screening (to order them), refits of
the leaders, held-out prediction of the best, and the verdict. The results are the types of
:mod:`.results`."""

from __future__ import annotations

import math
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable, Optional, Sequence, Union

import numpy as np
from numpy.typing import NDArray

from ..declarations import GRAVITY
from ..recording import Recording, load_case
from .case_model import FIT_DT, CaseSimulator, ModelSpec, Structure
from .calibration import Calibration, search
from .calibration import calibrate as global_calibration
from .catalogue import CALIBRATED, CALIBRATION_RANGE, CALIBRATION_SCALE, CATALOGUE, Effect
from .fitting import FitResult, FreeParam, Objective, apply, fit, fit_progressive, set_effect, set_param
from .locate import locate, merge_windows
from .noise import NoiseEstimate, estimate_noise
from .results import (BIC_THRESHOLD, NOISE_RATIO_OK, NULL_SIGMAS, REFIT_TOP, SEPARATION, WHITENESS_Z,
                      Candidate, Diagnosis)
from .screening import Screened, screen

#: leading candidates whose nominal parameters seed a refit of the null model
NULL_REFITS = 2
#: least-squares evaluations of the final polish of the leading candidate
POLISH_NFEV = 25
#: leading candidates fitted with a population search of their own, and its settings
GLOBAL_CANDIDATES = 2
CANDIDATE_SEARCH_CYCLES = 2
CANDIDATE_POPULATION = 5
CANDIDATE_GENERATIONS = 20


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


def _set_tied_friction(params: dict, effects: dict, value: float) -> None:
    # a nominal without a Stribeck peak (mu_s <= mu_k) keeps none as its level is calibrated:
    # mu_s follows mu_k, exactly as the stribeck candidate's model at "no effect"
    params["mu_k"] = value
    params["mu_s"] = value


def _calibration_params(p: dict) -> list[FreeParam]:
    """The calibrated subset as free parameters within CALIBRATION_RANGE of the nominal values;
    mu_k carries mu_s along when the nominal has no Stribeck peak."""
    lo, hi = CALIBRATION_RANGE
    tied = p["mu_s"] <= p["mu_k"]
    return [FreeParam(n, p[n], lo * p[n], hi * p[n], CALIBRATION_SCALE * p[n],
                      _set_tied_friction if (n == "mu_k" and tied) else set_param(n)) for n in CALIBRATED]


@dataclass
class _Problem:
    """What every stage works on: the recording, its noise, the simulator and the objective."""

    rec: Recording
    noise: NoiseEstimate
    sim: CaseSimulator
    obj: Objective
    tick: Optional[Callable[..., Any]]  #: progress bar update, or None

    @property
    def sigma(self) -> float:
        return self.noise.sigma

    @property
    def n_offsets(self) -> int:
        return self.obj.n_offsets

    @property
    def ln_n(self) -> float:
        return math.log(self.obj.n)


@dataclass
class _Nominal:
    """The nominal model as given, and its misfit (offsets fitted)."""

    structure: Structure
    params: dict[str, Any]  #: [SI]; normal_force None where meta's value is the derived one
    spec: ModelSpec
    residuals: list[NDArray[np.float64]]
    chi2: float


@dataclass
class _Calibration:
    """The calibrated nominal subset: over the first cycle, then over everything."""

    free: list[FreeParam]
    one_cycle: FitResult
    one_cycle_at: list[FreeParam]  #: `free` centred on the one-cycle optimum
    fit: FitResult
    at: list[FreeParam]  #: `free` centred on the full-horizon optimum
    bic: float
    whiteness_z: float
    search: Calibration  #: the population search and its polishes (convergence evidence)


@dataclass
class _FirstFit:
    """One effect fitted over the first drive cycle with the calibrated subset."""

    effect: Effect
    fit: FitResult
    free: list[FreeParam]  #: calibrated subset + effect parameters, at their starting values
    base: ModelSpec  #: the one-cycle calibration with the effect's structure


@dataclass
class _Refit:
    """A ranked candidate with what its held-out prediction refits from."""

    candidate: Candidate
    base: ModelSpec
    free: list[FreeParam]  #: centred on the candidate's optimum


class _Clock:
    """Seconds per stage; a stage run twice (held-out) sums. Tells the progress bar, if any,
    that the stage is done."""

    def __init__(self, progress: Optional["_Progress"] = None) -> None:
        self.timings: dict[str, float] = {}
        self._last = time.perf_counter()
        self._progress = progress

    def lap(self, name: str) -> None:
        now = time.perf_counter()
        self.timings[name] = self.timings.get(name, 0.0) + now - self._last
        self._last = now
        if self._progress is not None:
            self._progress.stage_done(name)


class _HeldOut:
    """Prediction of one experiment by a model refitted on the others (the largest experiment of
    a direction that has at least two)."""

    def __init__(self, pb: _Problem) -> None:
        self.pb = pb
        self.index = _heldout_index(pb.rec)
        train = [i for i in range(len(pb.rec.experiments)) if i != self.index]
        self.obj = Objective(pb.rec, pb.sim, pb.sigma, train)

    def rms(self, spec: ModelSpec, free: Sequence[FreeParam]) -> float:
        """RMS [m] of the held-out experiment's residual (its own offset removed)."""
        # refit on the training experiments from the full-data solution, then predict
        start = [f.at(f.value(0.0)) for f in free]
        r = fit(self.obj, spec, start, max_nfev=8, progress=self.pb.tick)
        pred = self.pb.sim.predict([r.spec])[0]
        d = self.pb.rec.experiments[self.index].x - pred[self.index]
        d = d - d.mean()
        return float(math.sqrt(np.mean(d * d)))


def _nominal(pb: _Problem) -> _Nominal:
    """The nominal model as given; the normal force follows the masses when meta's value does."""
    nom = pb.rec.nominal
    p0: dict[str, Any] = nom.params.to_dict(resolved=False)
    derived = (p0["m1"] + p0["m2"] + nom.params.pe_mass) * GRAVITY
    if p0.get("normal_force") is not None and abs(p0["normal_force"] / derived - 1.0) < 1e-5:
        p0["normal_force"] = None
    structure = Structure(nom.model, nom.n_elements, nom.piezo_hysteresis)
    spec = ModelSpec(structure, p0, {})
    res, _ = pb.obj.profiled(pb.sim.predict([spec])[0])
    chi2 = float(sum(np.sum(r * r) for r in res)) / pb.sigma**2
    return _Nominal(structure, p0, spec, res, chi2)


def _calibrate(pb: _Problem, nominal: _Nominal) -> _Calibration:
    """Calibrate the plausibly-off nominal parameters globally (see :mod:`.calibration`): a
    population search over their plausible ranges on the segmented misfit, then independent
    least-squares polishes over everything."""
    free = _calibration_params(nominal.params)
    g = global_calibration(pb.obj, nominal.spec, free, progress=pb.tick)
    cal = g.fit
    at = [f.at(cal.values[f.name]) for f in free]
    bic = cal.chi2 + (len(free) + pb.n_offsets) * pb.ln_n
    # the one-cycle optimum (the search's best member): where the candidates' one-cycle fits
    # start, since over everything a missing effect may have pulled the nominal values away
    u = g.search_u if g.search_u is not None else np.zeros(len(free))
    one_at = [f.at(f.value(float(x))) for f, x in zip(free, u)]
    one_spec = apply(nominal.spec, free, u)
    one = FitResult({f.name: f.value(float(x)) for f, x in zip(free, u)}, dict(cal.std), g.search_best,
                    pb.obj.with_cycles(1).n, [], [], one_spec, g.evaluations, True, "population search, one cycle")
    return _Calibration(free, one, one_at, cal, at, bic, whiteness_z(cal.residuals), g)


def _starts(eff: Effect) -> list[list[FreeParam]]:
    """The effect's parameters at every combination of their starting values."""
    grids = [ep.starts for ep in eff.params]
    combos = [tuple(s) for s in np.array(np.meshgrid(*grids, indexing="ij")).reshape(len(grids), -1).T] if grids else [()]
    return [[ep.free(v) for ep, v in zip(eff.params, c)] for c in combos]


def _one_cycle_fits(pb: _Problem, nominal: _Nominal, cal: _Calibration) -> list[_FirstFit]:
    """Every applicable effect fitted over the first cycle, where the misfit is smooth (a
    linearisation about the calibration is not enough: when an effect is large, the
    nominal-only calibration compensates it with far-off parameters)."""
    obj1 = pb.obj.with_cycles(1)
    cal1, cal1_at = cal.one_cycle, cal.one_cycle_at
    first: list[_FirstFit] = []
    for eff in [e for e in CATALOGUE if e.applies(nominal.structure, nominal.params)]:
        base = ModelSpec(eff.structure(nominal.structure), dict(cal1.spec.params), dict(cal1.spec.effects))
        starts = _starts(eff)
        if len(starts) > 1:  # the best multi-start value, judged over the first cycle
            preds = obj1.predict([apply(base, cal1_at + st, np.zeros(len(cal1_at) + len(st))) for st in starts])
            st = starts[int(np.argmin([float(np.sum(obj1.vector(p) ** 2)) for p in preds]))]
        else:
            st = starts[0]
        free = cal1_at + st
        first.append(_FirstFit(eff, fit(obj1, base, free, max_nfev=10, progress=pb.tick), free, base))
    return first


def _order_by_screening(pb: _Problem, cal: _Calibration, first: list[_FirstFit]
                        ) -> tuple[list[_FirstFit], dict[str, Screened]]:
    """The one-cycle fits ordered by their best rank in either BIC over the first cycle or the
    screened chi^2 drop about the full-horizon calibration (effects that grow over the cycles —
    a ground spring, drift, creep — can hide in the first one); and the screening by id."""
    screened = {s.effect.id: s for s in screen(pb.obj, cal.fit, cal.at, [f.effect for f in first], pb.sigma)}
    ln_n1 = math.log(pb.obj.with_cycles(1).n)
    bic1 = {f.effect.id: f.fit.chi2 + len(f.free) * ln_n1 for f in first}
    rank1 = {k: i for i, k in enumerate(sorted(bic1, key=bic1.get))}
    rank_all = {k: i for i, k in enumerate(sorted(screened, key=lambda k: -screened[k].delta_chi2))}
    order = sorted(first, key=lambda f: (min(rank1[f.effect.id], rank_all[f.effect.id]), rank1[f.effect.id]))
    return order, screened


def _refit(pb: _Problem, cal: _Calibration, first: list[_FirstFit], screened: dict[str, Screened],
           refit_top: int) -> list[_Refit]:
    """The leading `refit_top` effects refitted over two cycles and everything, from their
    one-cycle fit or from the screened estimate, whichever fits the first two cycles better;
    the rest reported with their one-cycle parameters, evaluated over everything."""
    obj2 = pb.obj.with_cycles(2)
    out: list[_Refit] = []
    for i, f in enumerate(first):
        eff, r1 = f.effect, f.fit
        start = [p.at(r1.values[p.name]) for p in f.free]
        if i < refit_top:
            if i < GLOBAL_CANDIDATES and not _leaves_noise(pb, cal):
                # the leading candidates get a population search of their own (the nominal-only
                # calibration may have compensated the effect with far-off parameters, a basin
                # the candidate's least squares could not leave), seeded with the one-cycle fit
                picks, _, _ = search(pb.obj, f.base, start, cycles=CANDIDATE_SEARCH_CYCLES,
                                     population_per_param=CANDIDATE_POPULATION,
                                     generations=CANDIDATE_GENERATIONS, progress=pb.tick)
                starts = [[p.at(p.value(float(x))) for p, x in zip(start, picks[0])]]
            else:  # the one-cycle fit, or the screened estimate
                starts = [start, cal.one_cycle_at + [ep.free(v) for ep, v in zip(eff.params, screened[eff.id].estimate)]]
            # ... or the null model it contains (the effect at "no effect"): whichever fits the
            # first two cycles best
            starts.append(cal.at + _null_effect_start(eff))
            chis = [obj2.chi2(apply(f.base, s_, np.zeros(len(s_)))) for s_ in starts]
            start = starts[int(np.argmin(chis))]
            r = fit_progressive(pb.obj, f.base, start, horizons=(2, None), max_nfev=(12, 10), progress=pb.tick)
            null = _at_null(cal, eff, f.base)
            if null is not None and r.chi2 >= null.chi2:
                # every candidate contains the null model: its fit never ends worse than it
                out.append(_Refit(_candidate(pb, cal, eff, null, False, at_null=True), f.base,
                                  [p.at(cal.fit.values[p.name]) if p.name in cal.fit.values else p for p in f.free]))
                continue
        else:
            spec = apply(f.base, start, np.zeros(len(start)))
            res, _ = pb.obj.profiled(pb.obj.predict([spec])[0])
            chi2 = float(sum(np.sum(x * x) for x in res)) / pb.sigma**2
            r = FitResult(r1.values, r1.std, chi2, pb.obj.n, res, [], spec, 0, True, "one-cycle fit only")
        cand = _candidate(pb, cal, eff, r, screened_only=i >= refit_top)
        out.append(_Refit(cand, f.base, [p.at(r.values[p.name]) for p in f.free]))
    return out


def _candidate(pb: _Problem, cal: _Calibration, eff: Effect, r: FitResult, screened_only: bool,
               at_null: bool = False) -> Candidate:
    k = len(cal.free) + len(eff.params) + pb.n_offsets
    bic = r.chi2 + k * pb.ln_n
    reported = eff.reported(r.values, r.std)
    names = [ep.name for ep in eff.params]
    significance = {ep.name: float(abs(r.values[ep.name] - ep.none) / r.std[ep.name] if r.std[ep.name] > 0 else math.inf)
                    for ep in eff.params}
    corr = {a: {b: r.corr.get(a, {}).get(b, math.nan) for b in names} for a in names} if len(names) > 1 else {}
    return Candidate(
        eff.id, eff.description, {n: v for n, (v, _) in reported.items()}, {ep.name: r.std[ep.name] for ep in eff.params},
        {n: r.values[n] for n in CALIBRATED}, r.chi2, k, bic, cal.bic - bic, r.rms, math.nan,
        whiteness_z(r.residuals), screened_only, r.residuals, r.spec,
        reported_std={n: s for n, (_, s) in reported.items() if s is not None},
        significance=significance, correlation=corr, at_null=at_null)


def _at_null(cal: _Calibration, eff: Effect, base: ModelSpec) -> Optional[FitResult]:
    """The candidate's own model with its effect at the "no effect" value and the nominal subset
    at the calibration: the null model it contains (None when the effect changes the structure,
    which has no such point)."""
    if not eff.params:
        return None
    values = dict(cal.fit.values)
    values.update({ep.name: ep.none for ep in eff.params})
    std = dict(cal.fit.std)
    std.update({ep.name: math.inf for ep in eff.params})
    spec = ModelSpec(base.structure, dict(cal.fit.spec.params), dict(cal.fit.spec.effects))
    for ep in eff.params:
        (ep.setter or set_effect(ep.name))(spec.params, spec.effects, ep.none)  # type: ignore[arg-type]
    return FitResult(values, std, cal.fit.chi2, cal.fit.n, cal.fit.residuals, cal.fit.offsets, spec, 0, True,
                     "the null model it contains")


def _null_refits(pb: _Problem, nominal: _Nominal, cal: _Calibration, refits: list[_Refit],
                  refit_top: int) -> tuple[_Calibration, str]:
    """The nominal model (no effect) refitted from the nominal parameters each leading candidate
    reached: a candidate's fit may find a better basin of the nominal subset, and that credit
    belongs to the null, not to the effect. The best nominal fit found anywhere is the null;
    every candidate's ΔBIC is then taken against it, and one no better than it is at null."""
    best, source = cal, "calibration"
    for r in sorted(refits, key=lambda x: x.candidate.chi2)[:refit_top]:
        c = r.candidate
        if c.screened_only or c.at_null:
            continue
        start = [f.at(c.calibrated[f.name]) for f in cal.free]
        n0 = fit(pb.obj, nominal.spec, start, max_nfev=10, progress=pb.tick)
        if n0.chi2 < best.fit.chi2 - 1e-6:
            at = [f.at(n0.values[f.name]) for f in cal.free]
            bic = n0.chi2 + (len(cal.free) + pb.n_offsets) * pb.ln_n
            best = _Calibration(cal.free, n0, at, n0, at, bic, whiteness_z(n0.residuals), cal.search)
            source = f"nominal refit from the {c.effect} fit"
    for r in refits:
        c = r.candidate
        c.delta_bic = best.bic - c.bic
        if c.chi2 >= best.fit.chi2:
            c.at_null = True
    return best, source


def _polish_leader(pb: _Problem, cal: _Calibration, refits: list[_Refit]) -> None:
    """The leading supported candidate fitted to convergence over everything from its optimum
    (the refits stop after a fixed budget): its residual is then judged, not the budget's."""
    lead = next((r for r in _ordered(refits) if _eligible(r.candidate)), None)
    if lead is None:
        return
    eff = next(e for e in CATALOGUE if e.id == lead.candidate.effect)
    base = ModelSpec(lead.base.structure, dict(lead.candidate.spec.params), dict(lead.candidate.spec.effects))
    r = fit(pb.obj, base, lead.free, max_nfev=POLISH_NFEV, progress=pb.tick)
    if r.chi2 < lead.candidate.chi2:
        c = _candidate(pb, cal, eff, r, screened_only=False)
        c.delta_bic = cal.bic - c.bic
        lead.candidate = c
        lead.free = [p.at(r.values[p.name]) for p in lead.free]


def _null_effect_start(eff: Effect) -> list[FreeParam]:
    """The effect's parameters at (next to) "no effect", as a least-squares start. A log-scaled
    parameter starts at its smallest starting value, not at the floor of its range: there the
    misfit hardly depends on log(value) and least squares would never leave it. (The guarantee
    that a candidate never ends worse than its null does not rest on this start; see `_at_null`.)"""
    return [ep.free(min(ep.starts) if ep.log else ep.none) for ep in eff.params]


def _leaves_noise(pb: _Problem, cal: _Calibration) -> bool:
    """The calibrated null's residual is noise: nothing large is compensated by far-off nominal
    values, so a candidate's least squares from the null it contains needs no global search."""
    return cal.fit.rms <= NOISE_RATIO_OK * pb.sigma and cal.whiteness_z <= WHITENESS_Z


def _finite(x: float) -> bool:
    return isinstance(x, float) and math.isfinite(x)


def _eligible(c: Candidate) -> bool:
    return not c.screened_only and c.present and c.delta_bic >= BIC_THRESHOLD


def _ordered(refits: list[_Refit]) -> list[_Refit]:
    """Refitted candidates first, present ones before those at or near "no effect", by ΔBIC."""
    return sorted(refits, key=lambda r: (r.candidate.screened_only, not r.candidate.present, -r.candidate.delta_bic))


def _rank_with_heldout(refits: list[_Refit], heldout: _HeldOut) -> list[Candidate]:
    """The candidates in rank order; the leading refitted one gets its held-out prediction."""
    refits = _ordered(refits)
    for r in [r for r in refits if _eligible(r.candidate)][:1]:
        r.candidate.heldout_rms = heldout.rms(r.base, r.free)
    return [r.candidate for r in refits]


def diagnose(case: Union[str, Path, Recording], *, progress: bool = True, dt: float = FIT_DT,
             threads: Optional[int] = None, refit_top: int = REFIT_TOP) -> Diagnosis:
    """Diagnose a recorded case (a directory in the `idm-recording/1` format, or a Recording)."""
    t_start = time.perf_counter()
    rec = case if isinstance(case, Recording) else load_case(case)
    bar = _bar(progress, rec.name)
    noise = estimate_noise(rec)
    sim = CaseSimulator(rec, dt=dt, threads=threads)
    pb = _Problem(rec, noise, sim, Objective(rec, sim, noise.sigma), bar.update if bar is not None else None)
    nominal = _nominal(pb)

    clock = _Clock(bar)
    cal = _calibrate(pb, nominal)
    clock.lap("calibration")
    heldout = _HeldOut(pb)
    first = _one_cycle_fits(pb, nominal, cal)
    clock.lap("one-cycle fits")
    first, screened = _order_by_screening(pb, cal, first)
    clock.lap("screening")
    refits = _refit(pb, cal, first, screened, refit_top)
    clock.lap("refits")
    cal, null_source = _null_refits(pb, nominal, cal, refits, NULL_REFITS)
    clock.lap("null refits")
    _polish_leader(pb, cal, refits)
    clock.lap("polish")
    ranking = _rank_with_heldout(refits, heldout)
    # the null's held-out prediction, for comparison, only where a candidate has one
    ho_cal = heldout.rms(cal.fit.spec, cal.at) if any(_finite(c.heldout_rms) for c in ranking) else math.nan
    clock.lap("held-out")
    locations, windows = locate(rec, cal.fit.residuals, pb.sigma)
    spans = merge_windows(windows, pb.sigma)

    verdict, reason, rms_after = _verdict(ranking, cal, noise, ho_cal)
    if bar is not None:
        bar.close()
    return Diagnosis(
        case=rec.name, verdict=verdict, reason=reason, ranking=ranking, noise=noise,
        rms_before=pb.sigma * math.sqrt(nominal.chi2 / pb.obj.n), rms_calibrated=cal.fit.rms, rms_after=rms_after,
        calibrated=cal.fit.values, calibrated_std=cal.fit.std, locations=locations, windows=spans,
        heldout_experiment=rec.experiments[heldout.index].name, heldout_rms_calibrated=ho_cal,
        whiteness_z_calibrated=cal.whiteness_z, seconds=time.perf_counter() - t_start, timings=clock.timings,
        simulations=sim.evaluations, recording=rec, nominal_residuals=nominal.residuals,
        calibrated_residuals=cal.fit.residuals, nominal_spec=nominal.spec, calibrated_spec=cal.fit.spec, simulator=sim,
        calibration_converged=cal.search.converged, calibration_summary=cal.search.summary(),
        calibration_chi2=[p.chi2 for p in cal.search.polishes], null_source=null_source,
    )


def _verdict(ranking: list[Candidate], cal: _Calibration, noise: NoiseEstimate, ho_cal: float
             ) -> tuple[str, str, float]:
    """An effect is the verdict only if it was refitted over everything, is present (no
    parameter within NULL_SIGMAS of "no effect"), improves BIC over the best null by
    BIC_THRESHOLD and leaves noise. Otherwise "none" when the null leaves noise; else
    "not_converged" when the calibration's independent searches disagreed (the tool's fit
    failed), else "unexplained"."""
    sigma = noise.sigma
    fit, wz_cal = cal.fit, cal.whiteness_z
    cal_ratio = fit.rms / sigma
    cal_is_noise = cal_ratio <= NOISE_RATIO_OK and wz_cal <= WHITENESS_Z
    eligible = [c for c in ranking if _eligible(c)]
    best = eligible[0] if eligible else None
    residual = f"RMS {cal_ratio:.2f} x noise, whiteness z = {wz_cal:.1f}"
    if best is None:
        if cal_is_noise:
            return ("none", f"after calibration the residual is noise ({residual}) and no effect is supported "
                    f"(ΔBIC ≥ {BIC_THRESHOLD:g} with its parameters beyond {NULL_SIGMAS:g} σ of 'no effect')", fit.rms)
        if not cal.search.converged:
            return ("not_converged", f"the calibration did not converge ({cal.search.summary()}) and a systematic "
                    f"residual remains ({residual}); no verdict on missing physics", fit.rms)
        return ("unexplained", f"a systematic residual remains after a converged calibration ({residual}) and "
                "no catalogue effect explains it", fit.rms)
    ratio = best.rms_after / sigma
    explained = ratio <= NOISE_RATIO_OK and best.whiteness_z <= WHITENESS_Z
    if not explained:
        if not cal.search.converged:
            return ("not_converged", f"the calibration did not converge ({cal.search.summary()}); the best effect "
                    f"({best.effect}) leaves RMS {ratio:.2f} x noise", fit.rms)
        return ("unexplained", f"the best effect ({best.effect}, ΔBIC {best.delta_bic:.0f}) leaves a systematic "
                f"residual (RMS {ratio:.2f} x noise, whiteness z = {best.whiteness_z:.1f})", fit.rms)
    others = [c for c in eligible[1:]]
    note = ""
    if others and best.delta_bic - others[0].delta_bic < SEPARATION:
        note = f"; runner-up {others[0].effect} is close (ΔBIC {others[0].delta_bic:.0f})"
    if _finite(best.heldout_rms) and _finite(ho_cal) and best.heldout_rms > ho_cal * 1.02:
        note += "; held-out prediction does not improve"
    return (best.effect, f"{best.effect} improves BIC by {best.delta_bic:.0f} over the best null fit and leaves noise "
            f"(RMS {ratio:.2f} x noise){note}", best.rms_after)


#: the diagnosis's stages: (name, share of a typical run's time [%], typical simulations), from
#: the dev-set timings (benches/RESULTS.md); the progress bar advances by stage with an ETA
STAGES: tuple[tuple[str, float, float], ...] = (
    ("calibration", 40.0, 1500.0),
    ("one-cycle fits", 8.0, 300.0),
    ("screening", 4.0, 50.0),
    ("refits", 36.0, 1500.0),
    ("null refits", 6.0, 200.0),
    ("polish", 4.0, 200.0),
    ("held-out", 2.0, 10.0),
)


class _Progress:
    """A percent bar over the stages: each stage owns its share, simulations advance it within the
    stage (approaching the share's end, as a stage's length is not known in advance), and the
    bar's ETA follows; the stage and the simulation count are shown beside it."""

    def __init__(self, name: str) -> None:
        from tqdm.auto import tqdm

        self.bar = tqdm(total=100.0, desc=f"diagnosing {name}", unit="%",
                        bar_format="{desc}: {percentage:3.0f}%|{bar}| [{elapsed}<{remaining}{postfix}]")
        self.stage, self.start, self.in_stage, self.evals = 0, 0.0, 0.0, 0
        self._show()

    def _show(self) -> None:
        name = STAGES[self.stage][0] if self.stage < len(STAGES) else "done"
        self.bar.set_postfix_str(f"{name}, {self.evals} simulations", refresh=False)

    def update(self, n: int = 1) -> None:
        """``n`` more simulations."""
        self.evals += int(n)
        if self.stage < len(STAGES):
            _, share, typical = STAGES[self.stage]
            self.in_stage += n
            target = self.start + share * (1.0 - 0.5 ** (self.in_stage / typical))
            self.bar.update(max(0.0, target - self.bar.n))
        self._show()

    def stage_done(self, name: str) -> None:
        while self.stage < len(STAGES):
            stage, share, _ = STAGES[self.stage]
            self.stage += 1
            self.start += share
            if stage == name:
                break
        self.in_stage = 0.0
        self.bar.update(max(0.0, self.start - self.bar.n))
        self._show()

    def close(self) -> None:
        self.bar.update(max(0.0, 100.0 - self.bar.n))
        self.bar.close()


def _bar(show: bool, name: str) -> Optional[_Progress]:
    return _Progress(name) if show else None
