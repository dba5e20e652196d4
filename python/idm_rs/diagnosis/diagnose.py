"""The diagnosis: calibrate the nominal model, locate the residual, try every catalogue effect,
rank them by information criterion and held-out prediction, and give a verdict.

:func:`diagnose` runs named stages in order: the nominal model as given, calibration, the
held-out split, one-cycle fits of every applicable effect, screening (to order them), refits of
the leaders, held-out prediction of the best, and the verdict. The results are the types of
:mod:`.results`."""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any, Callable, Optional, Sequence, Union

import numpy as np
from numpy.typing import NDArray

from ..declarations import GRAVITY
from ..engine import DivergenceError
from ..recording import Recording, load_case
from .calibration import Calibration, scan_starts, search
from .calibration import calibrate as global_calibration
from .case_model import FIT_DT, CaseSimulator, ModelSpec, Structure
from .catalogue import CALIBRATED, CALIBRATION_RANGE, CALIBRATION_SCALE, CATALOGUE, Effect, EffectParam
from .discovery import Discovery, NumericalFailure
from .discovery import discover as run_discovery
from .fitting import FitResult, FreeParam, Objective, apply, fit, set_effect, set_param
from .identifiability import assess
from .locate import Location, locate, merge_windows
from .multistart import Start, agree, multistart
from .next_experiment import ParameterProposal, Proposal, propose, propose_for_heldout, propose_for_parameter
from .noise import NoiseEstimate, cross_check, estimate_noise, whiteness_z
from .results import Alternative, Candidate, Diagnosis, SecondSearch
from .screening import Screened, near_degenerate, screen
from .thresholds import BIC_THRESHOLD, LR_ALPHA, NOISE_RATIO_OK, REFIT_TOP, SEPARATION, WHITENESS_Z

#: leading candidates whose nominal parameters seed a refit of the null model
NULL_REFITS = 1
#: least-squares evaluations of the final polish of the leading candidate (and of rivals within
#: SEPARATION of it, at most POLISH_CLOSE candidates in all)
POLISH_NFEV = 12
POLISH_CLOSE = 3
#: multiples of an effect parameter's fit scale its multistart tries (both signs where signed)
MAGNITUDES = (1.0, 3.0, 10.0, 30.0)
#: the wider search: every candidate's population search (per free parameter, generations) over
#: the first cycle, and the candidates that then get local fits
WIDE_POPULATION = 5
WIDE_GENERATIONS = 10
WIDE_FITS = 2
#: a candidate whose screening score (the chi^2 a linearised step would gain) is below this is
#: not fitted in the first round: it cannot approach BIC_THRESHOLD + its parameters' penalty
#: (the wider search, run when the residual is systematic, fits every candidate regardless)
MIN_SCORE = 5.0
#: a candidate's local fits: the horizons (drive cycles; None: everything) fitted in turn, and
#: least-squares evaluations at each. Everything at once: a recording holds only 2-5 drive
#: cycles, so two cycles save little, and their optimum can lie elsewhere (confusion case 6:
#: from the nominal values with a spring of 3e4 N/m, 8+8 evaluations over two cycles then
#: everything ended at chi^2 6.3e6 with mu_k at its bound; 12 over everything reach the truth).
#: 16: in confusion case 1 the fit that reaches the truth (5,324) stands at 131,830 after 8,
#: behind a local minimum's 17,600 (a short fit for all, a long one for the best, misses it)
CANDIDATE_HORIZONS: tuple[Optional[int], ...] = (None,)
CANDIDATE_NFEV: tuple[int, ...] = (16,)
#: local fits per candidate's multistart from its best distinct ranked starts (the best start at
#: the nominal values as given gets one more)
CANDIDATE_FITS = 1


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
    search: Calibration  #: the population search and its local fits (convergence evidence)
    #: `free` at the best 1-D scan start (the nominal values with a side basin left), or None
    scan_at: Optional[list[FreeParam]] = None


@dataclass
class _Refit:
    """A ranked candidate with what its held-out prediction refits from."""

    candidate: Candidate
    base: ModelSpec
    free: list[FreeParam]  #: centred on the candidate's optimum (nominal subset + effect)


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
        r = fit(self.obj, spec, start, max_nfev=4, progress=self.pb.tick)
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
    scan_at = [f.at(f.value(float(x))) for f, x in zip(free, g.scan_u)] if g.scan_u is not None else None
    return _Calibration(free, one, one_at, cal, at, bic, whiteness_z(cal.residuals), g, scan_at)


def _magnitudes(ep: EffectParam) -> list[float]:
    """An effect parameter's starting values: a log-scaled one (a time constant) at its
    catalogue starts; any other at half-decade multiples of its fit scale (both signs where
    "no effect" lies inside its bounds), and at "no effect"."""
    if ep.log:
        return list(ep.starts)
    out = [ep.none]
    for m in MAGNITUDES:
        for sign in (1.0, -1.0):
            v = ep.none + sign * m * ep.scale
            if ep.lower <= v <= ep.upper:
                out.append(v)
    return out


def _candidate_starts(pb: _Problem, cal: _Calibration, eff: Effect, sc: Optional[Screened]) -> list[Start]:
    """A candidate's multistart: the nominal subset at the best null fit, at the one-cycle
    optimum, at the nominal values as given (a large missing effect can pull the null fit far
    from them), at the calibration's best 1-D scan start and at its other optima as good as
    the best, and after the screening step, each with the
    effect's magnitude on a small log grid (both signs where signed) — the null itself (the
    effect at "no effect") among them — plus the screening step's own estimate."""
    nominal: list[tuple[str, list[FreeParam]]] = [("null fit", cal.at), ("one-cycle optimum", cal.one_cycle_at),
                                                  ("nominal values", cal.free)]
    if cal.scan_at is not None:
        # the nominal values with a side basin left (the calibration's best 1-D scan start),
        # ranked with the rest; not in the nominal values' group, whose best start always gets
        # a fit: with a large effect missing the scan start can outrank the nominal values at
        # every magnitude although only they lead to the truth (confusion case 6: a spring to
        # ground with m2 mis-set). Where the scan found the null's basin, the null fit is in it.
        nominal.append(("1-D scan", cal.scan_at))
    # the calibration's other optima as good as the best (see `multistart.agree`): a missing
    # effect leaves the null several equally bad basins, and the effect may be reachable by
    # least squares from one of them only (ranked with the rest, no fit of their own)
    optima = cal.search.polishes if cal.search is not None else []
    for k, p in enumerate(optima[1:], 2):
        if agree(optima[0], p.chi2):
            nominal.append((f"null optimum {k}", [f.at(p.values[f.name]) for f in cal.free]))
    if sc is not None and sc.nominal_step is not None:
        nominal.append(("score step", [f.at(f.value(float(d))) for f, d in zip(cal.at, sc.nominal_step)]))
    grids = [_magnitudes(ep) for ep in eff.params]
    combos = ([tuple(c) for c in np.array(np.meshgrid(*grids, indexing="ij")).reshape(len(grids), -1).T]
              if grids else [()])
    starts = []
    for label, nom in nominal:
        for c in combos:
            what = ", ".join(f"{ep.name}={v:.3g}" for ep, v in zip(eff.params, c))
            starts.append(Start(f"{label}; {what}" if what else label,
                                list(nom) + [ep.free(v) for ep, v in zip(eff.params, c)], label))
    if sc is not None and sc.nominal_step is not None and eff.params:
        what = ", ".join(f"{ep.name}={v:.3g}" for ep, v in zip(eff.params, sc.estimate))
        starts.append(Start(f"score step; {what}",
                            nominal[-1][1] + [ep.free(v) for ep, v in zip(eff.params, sc.estimate)], "score step"))
    return starts


def _screen(pb: _Problem, cal: _Calibration, nominal: _Nominal) -> tuple[list[Effect], dict[str, Screened]]:
    """Every applicable effect scored at the null optimum, best score first."""
    effects = [e for e in CATALOGUE if e.applies(nominal.structure, nominal.params)]
    screened = {s.effect.id: s for s in screen(pb.obj, cal.fit, cal.at, effects, pb.sigma, pb.tick)}
    return sorted(effects, key=lambda e: -screened[e.id].delta_chi2), screened


def _fit_candidates(pb: _Problem, cal: _Calibration, order: list[Effect], screened: dict[str, Screened],
                    refit_top: int, already: Optional[list[_Refit]] = None, local_fits: int = CANDIDATE_FITS,
                    min_score: float = MIN_SCORE, sink: Optional[list[_Refit]] = None) -> list[_Refit]:
    """The `refit_top` best-scored effects (those scoring at least `min_score`) fitted by
    multistart over two cycles, then everything; the others reported with their score's
    linearised step only. A fit that ends no better than the null model it contains is
    reported at the null."""
    done = {r.candidate.effect: r for r in (already or []) if not r.candidate.screened_only}
    # each finished candidate goes straight into `sink` (kept if the run is interrupted)
    out: list[_Refit] = sink if sink is not None else []
    for i, eff in enumerate(order):
        sc = screened[eff.id]
        base = ModelSpec(eff.structure(cal.fit.spec.structure), dict(cal.fit.spec.params), dict(cal.fit.spec.effects))
        free = cal.at + [ep.free(v) for ep, v in zip(eff.params, sc.estimate)]
        if eff.id in done:
            out.append(done[eff.id])
            continue
        if i >= refit_top or (sc.delta_chi2 < min_score):
            # not fitted: the score's linearised step, evaluated without a simulation
            chi2 = max(cal.fit.chi2 - sc.delta_chi2, 0.0)
            values = dict(cal.fit.values)
            values.update({ep.name: v for ep, v in zip(eff.params, sc.estimate)})
            r = FitResult(values, {k: math.inf for k in values}, chi2, pb.obj.n, cal.fit.residuals, [],
                          apply(base, free, np.zeros(len(free))), 0, True, "screened: the score's linearised step only")
            c = _candidate(pb, cal, eff, r, screened_only=True)
            c.score = sc.delta_chi2
            out.append(_Refit(c, base, free))
            continue
        ms = multistart(pb.obj, base, _candidate_starts(pb, cal, eff, sc), local_fits=local_fits,
                        horizons=CANDIDATE_HORIZONS, max_nfev=CANDIDATE_NFEV, always=("nominal values",),
                        stop_at_noise=True, progress=pb.tick)
        r = ms.best
        null = _at_null(cal, eff, base)
        if null is not None and r.chi2 >= null.chi2:
            # every candidate contains the null model: its fit never ends worse than it
            c = _candidate(pb, cal, eff, null, False, at_null=True)
            c.multistart = ms.to_dict()
            c.score = sc.delta_chi2
            out.append(_Refit(c, base, [p.at(cal.fit.values[p.name]) if p.name in cal.fit.values else p for p in free]))
            continue
        c = _candidate(pb, cal, eff, r, screened_only=False)
        c.multistart = ms.to_dict()
        c.score = sc.delta_chi2
        out.append(_Refit(c, base, [p.at(r.values[p.name]) for p in free]))
    return out


def _wide_search(pb: _Problem, cal: _Calibration, order: list[Effect], screened: dict[str, Screened],
                 first: list[_Refit]) -> list[_Refit]:
    """Every candidate's own population search over its first cycle (nominal subset within its
    plausible ranges and the effect within its fit bounds, the best null found so far with the
    effect's first start one member): a large missing effect can pull the null fit — and every
    start built on it — into a basin of the nominal parameters from which no local fit finds
    the truth. The WIDE_FITS best searched effects then get multistart local fits from the
    search's distinct good members, their first-round fit, the best null and the nominal
    values (each with the effect's magnitude grid)."""
    by_id = {r.candidate.effect: r for r in first}
    searched: list[tuple[float, Effect, list[Start]]] = []
    for eff in order:
        sc = screened[eff.id]
        base = ModelSpec(eff.structure(cal.fit.spec.structure), dict(cal.fit.spec.params), dict(cal.fit.spec.effects))
        # the search's box: the nominal subset's plausible ranges (bounds are absolute), centred
        # on the best null so far; the effect's first non-null start
        start = list(cal.at) + [ep.free(_magnitudes(ep)[1 if not ep.log and len(_magnitudes(ep)) > 1 else 0])
                                for ep in eff.params]
        picks, best, _ = search(pb.obj, base, start, cycles=1, population_per_param=WIDE_POPULATION,
                                generations=WIDE_GENERATIONS, progress=pb.tick)
        starts = [Start("population search best" if k == 0 else f"population search member {k + 1}",
                        [f.at(f.value(float(x))) for f, x in zip(start, u)], "population search best" if k == 0 else "")
                  for k, u in enumerate(picks)]
        prev = by_id.get(eff.id)
        if prev is not None and not prev.candidate.screened_only:
            starts.append(Start("first-round fit", list(prev.free), "first-round fit"))
        starts += [st for st in _candidate_starts(pb, cal, eff, sc) if st.group in ("null fit", "nominal values")]
        searched.append((best, eff, starts))
    searched.sort(key=lambda x: x[0])
    out = {r.candidate.effect: r for r in first}
    for _, eff, starts in searched[:WIDE_FITS]:
        base = ModelSpec(eff.structure(cal.fit.spec.structure), dict(cal.fit.spec.params), dict(cal.fit.spec.effects))
        ms = multistart(pb.obj, base, starts, local_fits=1, horizons=(2, None), max_nfev=(10, 10),
                        always=("population search best", "null fit"), progress=pb.tick)
        r = ms.best
        old = out.get(eff.id)
        if old is not None and not old.candidate.screened_only and old.candidate.chi2 <= r.chi2:
            continue
        null = _at_null(cal, eff, base)
        if null is not None and r.chi2 >= null.chi2:
            continue
        c = _candidate(pb, cal, eff, r, screened_only=False)
        c.multistart = ms.to_dict()
        c.score = screened[eff.id].delta_chi2
        out[eff.id] = _Refit(c, base, [p.at(r.values[p.name]) for p in starts[0].free])
    return list(out.values())


def _candidate(pb: _Problem, cal: _Calibration, eff: Effect, r: FitResult, screened_only: bool,
               at_null: bool = False) -> Candidate:
    k = len(cal.free) + len(eff.params) + pb.n_offsets
    bic = r.chi2 + k * pb.ln_n
    reported = eff.reported(r.values, r.std)
    names = [ep.name for ep in eff.params]
    significance = {ep.name: float(abs(r.values[ep.name] - ep.none) / r.std[ep.name]
                                   if r.std[ep.name] > 0 else math.inf)
                    for ep in eff.params}
    corr = {a: {b: r.corr.get(a, {}).get(b, math.nan) for b in names} for a in names} if len(names) > 1 else {}
    return Candidate(
        eff.id, eff.description, {n: v for n, (v, _) in reported.items()},
        {ep.name: r.std[ep.name] for ep in eff.params},
        {n: r.values[n] for n in CALIBRATED}, r.chi2, k, bic, cal.bic - bic, r.rms, math.nan,
        whiteness_z(r.residuals), screened_only, r.residuals, r.spec,
        reported_std={n: s for n, (_, s) in reported.items() if s is not None},
        significance=significance, correlation=corr, at_null=at_null, lr_chi2=cal.fit.chi2 - r.chi2,
        identifiability=assess(r.values, r.std, r.corr, names + [n for n in cal.fit.values if n not in names]),
        calibrated_std={n: r.std[n] for n in CALIBRATED if n in r.std})


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
    params, effects = dict(cal.fit.spec.params), dict(cal.fit.spec.effects)
    spec = ModelSpec(base.structure, params, effects)
    for ep in eff.params:
        (ep.setter or set_effect(ep.name))(params, effects, ep.none)
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
        if c.screened_only or c.at_null or c.delta_bic < BIC_THRESHOLD:
            continue  # only a candidate that could win needs its credit checked
        start = [f.at(c.calibrated[f.name]) for f in cal.free]
        n0 = fit(pb.obj, nominal.spec, start, max_nfev=6, progress=pb.tick)
        if n0.chi2 < best.fit.chi2 - 1e-6:
            at = [f.at(n0.values[f.name]) for f in cal.free]
            bic = n0.chi2 + (len(cal.free) + pb.n_offsets) * pb.ln_n
            best = _Calibration(cal.free, n0, at, n0, at, bic, whiteness_z(n0.residuals), cal.search, cal.scan_at)
            source = f"nominal refit from the {c.effect} fit"
    for r in refits:
        _against_null(pb, best, r)
    return best, source


def _against_null(pb: _Problem, null: _Calibration, r: _Refit) -> None:
    """Take `r`'s ΔBIC and likelihood ratio against `null`; a candidate that ended no better
    than it is reported at the null it contains (its effect at "no effect", the null's fit,
    residual and nominal values): never worse than the null, never a significance of its own."""
    c = r.candidate
    if c.chi2 >= null.fit.chi2:
        if c.screened_only:
            # the score's linearised step, taken at an earlier null: no better than this one
            c.chi2, c.rms_after, c.residuals = null.fit.chi2, null.fit.rms, null.fit.residuals
            c.bic = c.chi2 + c.n_params * pb.ln_n
        else:
            eff = next(e for e in CATALOGUE if e.id == c.effect)
            at = _at_null(null, eff, r.base)
            if at is not None:
                nc = _candidate(pb, null, eff, at, False, at_null=True)
                nc.score, nc.multistart = c.score, c.multistart
                r.candidate = c = nc
                r.free = [p.at(null.fit.values[p.name]) if p.name in null.fit.values else p for p in r.free]
            c.at_null = True
    c.delta_bic = null.bic - c.bic
    c.lr_chi2 = null.fit.chi2 - c.chi2


def _polish_leader(pb: _Problem, cal: _Calibration, refits: list[_Refit]) -> None:
    """The leading supported candidate — and every supported one within SEPARATION of it in
    ΔBIC (at most POLISH_CLOSE in all) — fitted to convergence over everything from its optimum
    (the candidate fits stop after a fixed budget): their residuals are then judged, and close
    rivals compared, at their optima, not at the budget's."""
    eligible = [r for r in _ordered(refits) if _eligible(r.candidate)]
    if not eligible:
        return
    lead_bic = eligible[0].candidate.delta_bic
    for r0 in [r for r in eligible if lead_bic - r.candidate.delta_bic < SEPARATION][:POLISH_CLOSE]:
        eff = next(e for e in CATALOGUE if e.id == r0.candidate.effect)
        spec = r0.candidate.spec
        assert spec is not None  # a fitted candidate has its model
        base = ModelSpec(r0.base.structure, dict(spec.params), dict(spec.effects))
        r = fit(pb.obj, base, r0.free, max_nfev=POLISH_NFEV, progress=pb.tick)
        if r.chi2 < r0.candidate.chi2:
            c = _candidate(pb, cal, eff, r, screened_only=False)
            c.delta_bic = cal.bic - c.bic
            c.score, c.multistart = r0.candidate.score, r0.candidate.multistart
            r0.candidate = c
            r0.free = [p.at(r.values[p.name]) for p in r0.free]


#: candidates fitted (multistart) in the search for a second effect, best screened first
SECOND_TOP = 2


def _next_experiment(pb: _Problem, refits: list[_Refit], winner: str, other: str) -> Optional[Proposal]:
    """The drive that best separates the verdict's refit from its alternative's
    (:mod:`.next_experiment`), each at its own optimum with its own free parameters."""
    by_id = {r.candidate.effect: r for r in refits if not r.candidate.screened_only}
    if winner not in by_id or other not in by_id:
        return None
    models = []
    for r in (by_id[winner], by_id[other]):
        models.append((apply(r.base, r.free, np.zeros(len(r.free))), list(r.free)))
    return propose(pb.rec, pb.sigma, (winner, other), models[0], models[1])


def _found_against_null(pb: _Problem, cal: _Calibration, found: Discovery) -> None:
    """A found term's gain, taken against the nominal model refitted from where the term's
    refit left the calibrated subset (as every catalogue candidate's is, _null_refits): the
    refit starts from the nominal values too, and a better basin of the nominal parameters it
    reaches is the null's credit, not the term's. When the term no longer pays by BIC_THRESHOLD
    there, it is not discovered (the reason says so, with both figures)."""
    r = found.refit
    if r is None:
        return
    start = [f.at(r.values[f.name]) for f in cal.free if f.name in r.values]
    if len(start) != len(cal.free):
        return
    n0 = fit(pb.obj, cal.fit.spec, start, max_nfev=6, progress=pb.tick)
    k = len(found.values)
    gain = min(cal.fit.chi2, n0.chi2) - r.chi2 - k * pb.ln_n
    found.delta_bic = min(found.delta_bic, gain)
    if gain < BIC_THRESHOLD:
        found.discovered = False
        found.reason = (f"{found.reason}; but the nominal model refitted from where the term's refit left the "
                        f"calibrated parameters reaches RMS {n0.rms / pb.sigma:.2f} x noise (the term "
                        f"{r.rms / pb.sigma:.2f}): ΔBIC {gain:.0f} < {BIC_THRESHOLD:g}, the gain was a better "
                        f"calibration, not the term")


def _term_alone(pb: _Problem, cal: _Calibration, found: Discovery) -> tuple[FitResult, list[FreeParam]]:
    """The form of `found` (found and refitted from the model with a first effect) refitted
    from the calibrated null without that effect, started at the found values: the term alone's
    refit and its library parameters."""
    from .discovery import _refit

    assert found.form is not None and found.refit is not None
    v = found.refit.values
    form = found.form
    alone_form = replace(form, coefficients={t.param: v.get(t.param, form.coefficients[t.param]) for t in form.terms},
                         wavelength=v.get("lib_wavelength", form.wavelength))
    start = [f.at(v.get(f.name, f.x0)) for f in cal.free]
    return _refit(pb.obj, cal.fit.spec, start, alone_form, pb.tick)


def _without_lead(pb: _Problem, cal: _Calibration, lead: _Refit, found: Discovery
                  ) -> tuple[float, FitResult, list[FreeParam]]:
    """ΔBIC of the discovered term with the first effect (`found`, discovered from the model
    with it) over the term alone, refitted from the calibrated null: the first effect must pay
    its own way beside the found term (it may have mimicked part of it). Returns (ΔBIC, the
    term alone's refit, its library parameters)."""
    assert found.refit is not None
    r0, lib = _term_alone(pb, cal, found)
    n_lib = len(lib)
    with_lead = found.refit.chi2 + (len(lead.free) + n_lib) * pb.ln_n
    alone = r0.chi2 + (len(cal.free) + n_lib) * pb.ln_n
    return alone - with_lead, r0, lib


def _alone_explains(pb: _Problem, cal: _Calibration, heldout: _HeldOut, ho_cal: float, lead: _Refit,
                    found: Discovery) -> Optional[Discovery]:
    """A form found from the model with a first effect that did not stand there, refitted
    alone from the calibrated null: the first effect may be spurious (it mimicked part of the
    missing force and, kept, spoils the held-out prediction). The form with the lowest RMS that
    gained by BIC is tried; it is returned as discovered when alone it leaves noise, predicts
    the held-out experiment to noise and better than the null, and improves BIC, else None."""
    tried = [t for t in [found, *found.tried] if t.refit is not None and t.form is not None and t.form.terms
             and t.delta_bic >= BIC_THRESHOLD]
    if not tried:
        return None
    best = min(tried, key=lambda t: t.rms_after)
    assert best.form is not None  # tried keeps found forms only
    r0, lib = _term_alone(pb, cal, best)
    delta_bic = cal.fit.chi2 - r0.chi2 - len(lib) * pb.ln_n
    ho = heldout.rms(r0.spec, [f.at(r0.values[f.name]) for f in list(cal.free) + lib])
    sigma = pb.sigma
    terms = ", ".join(t.symbol for t in best.form.terms)
    if not (delta_bic >= BIC_THRESHOLD and r0.rms <= NOISE_RATIO_OK * sigma and ho <= NOISE_RATIO_OK * sigma
            and ho < ho_cal):
        found.reason += (f"; without {lead.candidate.effect}, the form {terms} alone leaves RMS "
                         f"{r0.rms / sigma:.2f} x noise, held out {ho / sigma:.2f} x noise (ΔBIC {delta_bic:.0f})")
        # kept among the forms tried (the experiment that would decide it is looked for there)
        found.tried.append(replace(best, refit=r0, rms_after=r0.rms, delta_bic=delta_bic, heldout_rms_after=ho,
                                   free=[f.at(r0.values[f.name]) for f in list(cal.free) + lib], tried=[]))
        return None
    from .discovery import _equation, describe

    out = replace(best, discovered=True, refit=r0, rms_after=r0.rms, delta_bic=delta_bic,
                  rms_before=cal.fit.rms, heldout_rms_before=ho_cal, heldout_rms_after=ho, tried=[])
    vals = {f.name: r0.values[f.name] for f in lib}
    out.values = {n: (x, r0.std.get(n)) for n, x in vals.items()}
    out.equation = _equation(best.form, vals)
    if best.body in best.forces:
        out.description = describe(best.form, vals, best.forces[best.body])
    where = "main body" if best.body == "main" else "weight"
    out.reason = (f"a force on the {where} of the form {terms}, found from the model with {lead.candidate.effect} "
                  f"(where it did not stand: {best.reason}), refitted without it: it improves BIC by "
                  f"{delta_bic:.0f} over the calibrated model (RMS {cal.fit.rms / sigma:.2f} → {r0.rms / sigma:.2f} "
                  f"x noise) and predicts the held-out experiment ({ho_cal * 1e9:.2f} → {ho * 1e9:.2f} nm); "
                  f"{lead.candidate.effect} had mimicked part of it")
    return out


def _travel_experiment(pb: _Problem, found: Discovery) -> Optional[ParameterProposal]:
    """For a discovery that did not stand because a form that leaves noise on every recording
    failed the held-out prediction, the drive after which the held-out check's training
    experiments would determine the form's least determined parameter (the wavelength of a
    periodic form; else the library coefficient with the largest relative 1-sigma):
    :func:`.next_experiment.propose_for_heldout`. The form is the one with the lowest RMS of
    those that leave noise and gain by BIC. None when no form left noise."""
    sigma = pb.sigma
    forms = [t for t in [found, *found.tried] if t.refit is not None and t.form is not None and t.form.terms
             and t.free and t.delta_bic >= BIC_THRESHOLD and t.rms_after <= NOISE_RATIO_OK * sigma
             and _finite(t.heldout_rms_after) and t.heldout_rms_after > NOISE_RATIO_OK * sigma]
    if not forms:
        return None
    best = min(forms, key=lambda t: t.rms_after)
    assert best.refit is not None and best.form is not None
    lib = {t.param for t in best.form.terms}
    if "lib_wavelength" in best.refit.values:
        name = "lib_wavelength"
    else:
        refit = best.refit
        name = max(lib, key=lambda n: (refit.std.get(n) or math.inf) / max(abs(refit.values[n]), 1e-300))
    p = propose_for_heldout(pb.rec, pb.sigma, name, (best.refit.spec, best.free), _heldout_index)
    terms = ", ".join(t.symbol for t in best.form.terms)
    if p is not None and p.heldout_now <= NOISE_RATIO_OK:
        # the experiments determine the form's parameters (to first order the held-out check
        # should pass): what fails is the form or the refit's nonlinearity, which no drive of
        # the grid is predicted to mend (the 11.8 um periodic friction: "sin, Ff sin, cos"
        # predicted at 1.00 x, measured 1.21 x — the true form is Ff sin, Ff cos)
        found.reason += (f"; the form {terms} is determined by the experiments other than the held-out one (its "
                         f"held-out RMS predicted to first order at {p.heldout_now:.2f} x noise, measured "
                         f"{best.heldout_rms_after / sigma:.2f} x): the form, not the experiments, falls short")
        return None
    if p is not None:
        p.context = (f"the form {terms} leaves {best.rms_after / sigma:.2f} x noise on the recordings but, refitted "
                     f"without {pb.rec.experiments[_heldout_index(pb.rec)].name}, predicts it at "
                     f"{best.heldout_rms_after / sigma:.2f} x noise: the other experiments leave {name} undetermined "
                     f"(its 1-sigma below is from the experiments the held-out check fits)")
    return p


def _determining_experiment(pb: _Problem, refits: list[_Refit], verdict: str) -> Optional[ParameterProposal]:
    """For a verdict naming one catalogue effect with an effect parameter the experiments do not
    determine (identifiability), the drive that would best determine it."""
    r = next((x for x in refits if x.candidate.effect == verdict and not x.candidate.screened_only), None)
    if r is None:
        return None
    eff = next(e for e in CATALOGUE if e.id == verdict)
    names = {ep.name for ep in eff.params}
    weak = [p for p in r.candidate.identifiability if p.name in names and not p.determined]
    if not weak:
        return None
    spec = apply(r.base, r.free, np.zeros(len(r.free)))
    return propose_for_parameter(pb.rec, pb.sigma, weak[0].name, (spec, list(r.free)))


def _structural_calibrations(pb: _Problem, cal: _Calibration, nominal: _Nominal, refits: list[_Refit]
                             ) -> list[_Refit]:
    """Every applicable candidate that is a structure alone (no parameter: pe_mass) calibrated
    globally in its structure (population search, ranked starts, local fits: the calibration
    itself); it replaces the candidate's first-round fit when it ends lower."""
    out = {r.candidate.effect: r for r in refits}
    for eff in CATALOGUE:
        if eff.params or not eff.applies(nominal.structure, nominal.params):
            continue
        base = ModelSpec(eff.structure(nominal.structure), dict(nominal.spec.params), dict(nominal.spec.effects))
        g = global_calibration(pb.obj, base, cal.free, progress=pb.tick)
        r = g.fit
        old = out.get(eff.id)
        if old is not None and not old.candidate.screened_only and old.candidate.chi2 <= r.chi2:
            continue
        c = _candidate(pb, cal, eff, r, screened_only=False)
        c.multistart = g.multistart.to_dict() if g.multistart is not None else {}
        if old is not None:
            c.score = old.candidate.score
        out[eff.id] = _Refit(c, base, [f.at(r.values[f.name]) for f in cal.free])
    return list(out.values())


def _partial_leader(pb: _Problem, refits: list[_Refit]) -> Optional[_Refit]:
    """The leading supported candidate when it does not explain the residual (a first effect
    that stands but leaves a systematic residual), else None."""
    eligible = [r for r in _ordered(refits) if _eligible(r.candidate)]
    if not eligible or _explains(pb, eligible[0].candidate):
        return None
    return eligible[0]


def _second_effect(pb: _Problem, cal: _Calibration, lead: _Refit, heldout: _HeldOut,
                   first_round: list[_Refit]) -> SecondSearch:
    """A second catalogue effect searched from the model *with* the first (`lead`): the first's
    optimum becomes the null of a second round (screening, multistart fits of the SECOND_TOP
    best scored, the polish) under the same rules as the first round (likelihood ratio, ΔBIC
    over the model with the first alone, a residual at noise, the held-out experiment predicted
    better). The pair is named only when, in addition, the first effect pays its own way beside
    the second: the second alone, refitted from the pair's values, must be worse than the pair by
    BIC_THRESHOLD (else the first round's leader only mimicked part of the second)."""
    first = lead.candidate
    out = SecondSearch(first=first, first_heldout_rms=first.heldout_rms)
    r1 = fit(pb.obj, lead.base, lead.free, max_nfev=POLISH_NFEV, progress=pb.tick)
    at1 = [f.at(r1.values[f.name]) for f in lead.free]
    bic1 = r1.chi2 + (len(at1) + pb.n_offsets) * pb.ln_n
    # the second round's starts: the first's optimum ("null fit") and, always fitted, the nominal
    # values as given with the first effect at its fit ("nominal values"): with two effects
    # missing, the calibration can sit in a basin that compensates both, which no local fit
    # from it leaves (an incline and a spring with the masses mis-set: m1, m2 and mu_k moved
    # 13-15 % to mimic them and the pair stopped at 5.5 x noise)
    calibrated_names = {f.name for f in cal.free}
    nominal_start = list(cal.free) + [f for f in at1 if f.name not in calibrated_names]
    # ignore: no population search behind this null (search None, which _candidate_starts handles)
    with_first = _Calibration(nominal_start, r1, at1, r1, at1, bic1, whiteness_z(r1.residuals), None)  # type: ignore[arg-type]
    structure = r1.spec.structure
    effects = [e for e in CATALOGUE if e.id != first.effect and e.applies(structure, r1.spec.params)]
    if not effects:
        out.reason = f"no other catalogue effect applies beside {first.effect}"
        return out
    screened = {s.effect.id: s for s in screen(pb.obj, r1, at1, effects, pb.sigma, pb.tick)}
    order = sorted(effects, key=lambda e: -screened[e.id].delta_chi2)
    refits = _fit_candidates(pb, with_first, order, screened, SECOND_TOP)
    _polish_leader(pb, with_first, refits)
    if not any(_explains(pb, r.candidate) for r in refits):
        # as in the first round: every candidate's own population search (over the first
        # effect's parameters too) before the answer may be "no second effect"
        refits = _wide_search(pb, with_first, order, screened, refits)
        _polish_leader(pb, with_first, refits)
    ranked = _ordered(refits)
    out.ranking = [r.candidate for r in ranked]
    best = next((r for r in ranked if _eligible(r.candidate)), None)
    if best is None:
        top = ranked[0].candidate if ranked else None
        out.reason = (f"no second effect is supported beside {first.effect}"
                      + (f" (best: {top.effect}, ΔBIC {top.delta_bic:.0f} over {first.effect} alone)" if top else ""))
        return out
    best = _rescanned(pb, with_first, next(e for e in CATALOGUE if e.id == best.candidate.effect), best)
    return _judge_pair(pb, cal, out, best, r1.chi2, heldout, first_round)


def _rescanned(pb: _Problem, null: _Calibration, eff: Effect, best: _Refit) -> _Refit:
    """A supported pair (`best`: the second effect `eff` beside the first, scored against `null`,
    the first alone, whose calibrated parameters are centred on the nominal values) that leaves a
    systematic residual, fitted again from the 1-D scans of its own model (`calibration.
    scan_starts`, as the calibration does) centred twice: on the pair's values, and on the
    nominal values with the effects at the pair's sizes. With two large effects missing, the
    calibration can sit in the side basin of a mass that sets a resonance, and a local fit with
    both effects in the model does not leave it (two-effect pair 9 of bench_confusion_beyond: a
    drag on the weight and thermal drift, m1 mis-set by 12 %: the true pair stopped at 1.70 x
    noise); from the nominal values with the effects near their sizes a 1-D scan of m2 finds the
    basin and the fit reaches the truth in 10 evaluations. Returns the best of these fits and
    `best` (unchanged when the pair already explains the data)."""
    if _explains(pb, best.candidate):
        return best
    nominal = {f.name: f for f in null.free if f.name in CALIBRATED}
    centres = [best.free, [nominal.get(f.name, f) for f in best.free]]
    out = best
    for centre in centres:
        for _, u in scan_starts(pb.obj, best.base, centre, progress=pb.tick):
            start = [f.at(f.value(float(x))) for f, x in zip(centre, u)]
            r = fit(pb.obj, best.base, start, max_nfev=POLISH_NFEV, progress=pb.tick)
            if r.chi2 < out.candidate.chi2:
                out = _Refit(_candidate(pb, null, eff, r, screened_only=False), best.base,
                             [f.at(r.values[f.name]) for f in best.free])
    return out


#: supported first-round candidates (best ΔBIC first) whose pairs are fitted jointly when the
#: search from the leader names no second effect, and the least-squares evaluations of each
#: joint fit (two-effect pair 3 of bench_confusion_beyond: from the nominal values with each
#: effect at its own fit alone, 24 evaluations reach noise; 12 stop at 2.06 x noise)
JOINT_TOP = 3
JOINT_NFEV = 30


def _joint_pair(pb: _Problem, cal: _Calibration, first_round: list[_Refit], heldout: _HeldOut
                ) -> Optional[SecondSearch]:
    """Two effects fitted together from the start each found alone. With two large effects
    missing, the calibration and each candidate's own fit settle in basins that compensate for
    the other effect (two-effect pair 3: an incline and a drag on the weight, the masses and
    the presliding stiffness mis-set; the leader, piezo creep, mimics parts of both and no
    second effect stands beside it), while each true effect's fit alone finds its own size
    (θ −0.0105 for −0.01, c_weight 50.9 for 50). Every pair of the JOINT_TOP supported
    first-round candidates is fitted by least squares from the nominal values as given, each
    effect at its fit alone; the lowest is judged by the second round's rules, its better-ranked
    effect taken as the first. None when fewer than two candidates are supported."""
    ranked = [r for r in _ordered(first_round) if _eligible(r.candidate)][:JOINT_TOP]
    structure, params = cal.fit.spec.structure, cal.fit.spec.params
    best: Optional[tuple[_Refit, _Refit, Effect, FitResult, ModelSpec, list[FreeParam]]] = None
    for i, ra in enumerate(ranked):
        ea = next(e for e in CATALOGUE if e.id == ra.candidate.effect)
        for rb in ranked[i + 1:]:
            eb = next(e for e in CATALOGUE if e.id == rb.candidate.effect)
            if not eb.applies(ea.structure(structure), params):
                continue
            base = ModelSpec(eb.structure(ea.structure(structure)), dict(params), dict(cal.fit.spec.effects))
            own = {ep.name for ep in ea.params} | {ep.name for ep in eb.params}
            start = list(cal.free) + [f for f in ra.free + rb.free if f.name in own]
            r = fit(pb.obj, base, start, max_nfev=JOINT_NFEV, progress=pb.tick)
            if best is None or r.chi2 < best[3].chi2:
                best = (ra, rb, eb, r, base, start)
    if best is None:
        return None
    ra, rb, eb, r, base, start = best
    first = ra.candidate
    if not _finite(first.heldout_rms):
        first = replace(first, heldout_rms=heldout.rms(ra.base, ra.free))
    # the first effect alone, as fitted in the first round, is the null the pair is scored against
    assert first.spec is not None  # a fitted candidate has its model
    r1 = FitResult({f.name: f.x0 for f in ra.free}, {}, first.chi2, pb.obj.n, first.residuals, [], first.spec, 0, True,
                   "the first round's fit")
    # ignore: no population search behind this null (search None, which _candidate_starts handles)
    with_first = _Calibration([f for f in start if f.name not in {ep.name for ep in eb.params}], r1, ra.free, r1,
                              ra.free, first.bic, first.whiteness_z, None)  # type: ignore[arg-type]
    refit = _rescanned(pb, with_first, eb, _Refit(_candidate(pb, with_first, eb, r, screened_only=False), base,
                                                   [f.at(r.values[f.name]) for f in start]))
    out = SecondSearch(first=first, first_heldout_rms=first.heldout_rms, joint=True, ranking=[refit.candidate])
    return _judge_pair(pb, cal, out, refit, first.chi2, heldout, first_round)


def _judge_pair(pb: _Problem, cal: _Calibration, out: SecondSearch, best: _Refit, chi2_first: float,
                heldout: _HeldOut, first_round: list[_Refit]) -> SecondSearch:
    """The rules a pair must pass to be named (`best`: the pair's refit, its candidate scored
    against the first effect alone, whose chi^2 is `chi2_first`): its residual is noise, the
    held-out experiment is predicted better than with the first alone, and the first pays its own
    way (the second alone, refitted from the pair's values, worse by BIC_THRESHOLD)."""
    first = out.first
    pair = best.candidate
    out.pair, out.free, out.base = pair, best.free, best.base
    out.over_first = pair.delta_bic
    # the first effect must pay its own way beside the second: the second alone, from the pair's
    # values with the first at "no effect"
    second_eff = next(e for e in CATALOGUE if e.id == pair.effect)
    alone = next((r for r in first_round if r.candidate.effect == pair.effect and not r.candidate.screened_only), None)
    base2 = ModelSpec(second_eff.structure(cal.fit.spec.structure), dict(cal.fit.spec.params),
                      dict(cal.fit.spec.effects))
    start2 = [f.at(pair.calibrated.get(f.name, f.x0)) for f in cal.free] + [
        next(p for p in best.free if p.name == ep.name) for ep in second_eff.params]
    r2 = fit(pb.obj, base2, start2, max_nfev=POLISH_NFEV, progress=pb.tick)
    chi2_alone = min(r2.chi2, alone.candidate.chi2) if alone is not None else r2.chi2
    k2 = len(cal.free) + len(second_eff.params) + pb.n_offsets
    out.over_second_alone = (chi2_alone + k2 * pb.ln_n) - pair.bic
    explains = _explains(pb, pair)
    out.heldout_rms = pair.heldout_rms = heldout.rms(best.base, best.free)
    improves = not (_finite(out.heldout_rms) and _finite(first.heldout_rms) and out.heldout_rms > first.heldout_rms)
    total = cal.fit.chi2 - pair.chi2
    if total > 0:
        out.shares = {first.effect: max(cal.fit.chi2 - chi2_first, 0.0) / total,
                      pair.effect: max(chi2_first - pair.chi2, 0.0) / total}
    sigma = pb.sigma
    if not explains:
        out.reason = (f"{pair.effect} beside {first.effect} improves BIC by {pair.delta_bic:.0f} but leaves a "
                      f"systematic residual (RMS {pair.rms_after / sigma:.2f} x noise, whiteness z = "
                      f"{pair.whiteness_z:.1f})")
    elif not improves:
        out.reason = (f"{pair.effect} beside {first.effect} leaves noise but does not predict the held-out "
                      f"experiment better ({first.heldout_rms * 1e9:.2f} → {out.heldout_rms * 1e9:.2f} nm)")
    elif out.over_second_alone < BIC_THRESHOLD:
        out.reason = (f"{pair.effect} alone explains nearly as much as with {first.effect} (ΔBIC "
                      f"{out.over_second_alone:.0f} < {BIC_THRESHOLD:g}): {first.effect} does not pay its own way")
    else:
        out.named = True
        share = ", ".join(f"{k} {100 * v:.0f} %" for k, v in out.shares.items())
        out.reason = (f"two effects: {first.effect} and {pair.effect}. With both the residual is noise (RMS "
                      f"{pair.rms_after / sigma:.2f} x noise); {pair.effect} improves BIC by {pair.delta_bic:.0f} "
                      f"over {first.effect} alone (which left RMS {first.rms_after / sigma:.2f} x noise, whiteness "
                      f"z = {first.whiteness_z:.1f}), the pair beats {pair.effect} alone by ΔBIC "
                      f"{out.over_second_alone:.0f}, and the held-out experiment is predicted better "
                      f"({first.heldout_rms * 1e9:.2f} → {out.heldout_rms * 1e9:.2f} nm); share of the improvement: "
                      f"{share}")
    return out


def _discovery_start(verdict: str, lead: Optional[_Refit], cal: _Calibration, nominal: _Nominal, ho_cal: float
                     ) -> tuple[ModelSpec, list[FreeParam], float, Optional[_Refit]]:
    """Where discovery starts: (the model, its free calibrated parameters centred there, the
    held-out RMS [m] a found term must beat, the first effect it is found beside or None).
    After "not_converged", the nominal values as given (the calibration's basins each
    compensate for the missing force their own way), judged against the calibrated null's
    held-out RMS; else from the model with the first effect when one stands; else from the
    calibrated null."""
    if verdict == "not_converged":
        return nominal.spec, list(cal.free), ho_cal, None
    if lead is not None:
        return apply(lead.base, lead.free, np.zeros(len(lead.free))), list(lead.free), lead.candidate.heldout_rms, lead
    return cal.fit.spec, list(cal.at), ho_cal, None


def _leaves_noise(pb: _Problem, cal: _Calibration) -> bool:
    """The calibrated null's residual is noise: nothing large is compensated by far-off nominal
    values, so a candidate's least squares from the null it contains needs no global search."""
    return cal.fit.rms <= NOISE_RATIO_OK * pb.sigma and cal.whiteness_z <= WHITENESS_Z


def _better_of(a: list[_Refit], b: list[_Refit]) -> list[_Refit]:
    """Per effect, the fitted candidate with the lower chi^2 of two rounds."""
    out = {r.candidate.effect: r for r in a}
    for r in b:
        old = out.get(r.candidate.effect)
        if old is None or (not r.candidate.screened_only
                           and (old.candidate.screened_only or r.candidate.chi2 < old.candidate.chi2)):
            out[r.candidate.effect] = r
    return list(out.values())


def _explains(pb: _Problem, c: Candidate) -> bool:
    """A supported candidate whose fit leaves noise (as the verdict requires)."""
    return _eligible(c) and c.rms_after <= NOISE_RATIO_OK * pb.sigma and c.whiteness_z <= WHITENESS_Z


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


@dataclass
class _Run:
    """What a diagnosis has finished so far, kept for an interrupted run."""

    stage: str = "the nominal model"
    pb: Optional[_Problem] = None
    nominal: Optional[_Nominal] = None
    cal: Optional[_Calibration] = None
    screened: dict[str, Screened] = field(default_factory=dict)
    #: the candidates fitted so far, each appended as it finishes
    refits: list[_Refit] = field(default_factory=list)
    timings: dict[str, float] = field(default_factory=dict)


def diagnose(case: Union[str, Path, Recording], *, progress: bool = True, dt: float = FIT_DT,
             threads: Optional[int] = None, refit_top: int = REFIT_TOP, discover: bool = True) -> Diagnosis:
    """Diagnose a recorded case (a directory in the `idm-recording/1` format, or a Recording).
    With `discover` (the default), a case no catalogue effect explains goes on to discovery
    (:mod:`.discovery`): the missing force inferred, its form found in a library, modelled and
    refitted; verdict "discovered" when it stands. Ctrl-C (KeyboardInterrupt) returns what was
    finished — the calibration and the candidates fitted so far — as a Diagnosis with verdict
    "interrupted" and ``complete`` False."""
    t_start = time.perf_counter()
    rec = case if isinstance(case, Recording) else load_case(case)
    noise = estimate_noise(rec)
    sim = CaseSimulator(rec, dt=dt, threads=threads)
    bar = _bar(progress, rec.name, lambda: sim.evaluations)
    run = _Run()
    # numpy's BLAS on one thread: the engine's threads own the cores, and OpenBLAS's own threads
    # spin-wait after every small factorisation of the fits, taking cycles from them (measured on
    # 2 cores: dev14 84.6 -> 78.3 s, mean of three alternating pairs, every result identical)
    from threadpoolctl import threadpool_limits  # with scikit-learn; lazily, as scipy

    try:
        with threadpool_limits(limits=1, user_api="blas"):
            d = _diagnose(rec, noise, sim, bar, run, refit_top, t_start, discover)
    except KeyboardInterrupt:
        if bar is not None:
            bar.close(done=False)
        return _interrupted(rec, noise, sim, run, t_start)
    if bar is not None:
        bar.close()
    return d


def _interrupted(rec: Recording, noise: NoiseEstimate, sim: CaseSimulator, run: _Run, t_start: float) -> Diagnosis:
    """The Diagnosis of a run stopped by Ctrl-C: what was finished, marked incomplete."""
    cal, nominal = run.cal, run.nominal
    n_all = run.pb.obj.n if run.pb is not None else max(rec.n_samples, 1)
    ranking = [r.candidate for r in _ordered(run.refits)]
    rms0 = (math.sqrt(sum(float(np.sum(r * r)) for r in nominal.residuals) / n_all) if nominal is not None
            else math.nan)
    locations: list[Location] = []
    if cal is not None:
        locations, _ = locate(rec, cal.fit.residuals, noise.sigma)
    fitted = sum(1 for c in ranking if not c.screened_only)
    return Diagnosis(
        case=rec.name, verdict="interrupted",
        reason=(f"stopped by Ctrl-C during {run.stage} after {time.perf_counter() - t_start:.0f} s; "
                f"finished: {'the calibration' if cal is not None else 'nothing past the nominal model'}"
                + (f" and {fitted} candidate fit{'s' if fitted != 1 else ''}" if fitted else "")
                + " (no verdict was reached)"),
        ranking=ranking, noise=noise, rms_before=rms0,
        rms_calibrated=cal.fit.rms if cal is not None else math.nan,
        rms_after=cal.fit.rms if cal is not None else math.nan,
        calibrated=dict(cal.fit.values) if cal is not None else {},
        calibrated_std=dict(cal.fit.std) if cal is not None else {}, locations=locations, windows=[],
        heldout_experiment="", heldout_rms_calibrated=math.nan,
        whiteness_z_calibrated=cal.whiteness_z if cal is not None else math.nan,
        seconds=time.perf_counter() - t_start, timings=run.timings, simulations=sim.evaluations, recording=rec,
        nominal_residuals=nominal.residuals if nominal is not None else [],
        calibrated_residuals=cal.fit.residuals if cal is not None else [],
        nominal_spec=nominal.spec if nominal is not None else None,
        calibrated_spec=cal.fit.spec if cal is not None else None, simulator=sim,
        calibration_converged=cal.search.converged if cal is not None else False,
        calibration_summary=cal.search.summary() if cal is not None else "",
        screening={k: v.delta_chi2 for k, v in sorted(run.screened.items(), key=lambda kv: -kv[1].delta_chi2)},
        complete=False,
    )


def _diagnose(rec: Recording, noise: NoiseEstimate, sim: CaseSimulator, bar: Optional[_Progress], run: _Run,
              refit_top: int, t_start: float, discover: bool = True) -> Diagnosis:
    pb = _Problem(rec, noise, sim, Objective(rec, sim, noise.sigma), bar.update if bar is not None else None)
    run.pb = pb
    nominal = run.nominal = _nominal(pb)

    clock = _Clock(bar)
    run.timings = clock.timings
    run.stage = "the calibration"
    cal = _calibrate(pb, nominal)
    # the noise floor cross-checked against the calibrated residual's high-frequency content
    noise = cross_check(noise, cal.fit.residuals)
    pb, cal = _renoised(pb, cal, noise)
    run.pb, run.cal = pb, cal
    clock.lap("calibration")
    run.stage = "the screening"
    heldout = _HeldOut(pb)
    order, screened = _screen(pb, cal, nominal)
    run.screened = screened
    clock.lap("screening")
    run.stage = "the candidate fits"
    refits = _fit_candidates(pb, cal, order, screened, refit_top, sink=run.refits)
    run.refits = refits
    clock.lap("candidate fits")
    run.stage = "the null refits"
    cal, null_source = _null_refits(pb, nominal, cal, refits, NULL_REFITS)
    run.cal = cal
    clock.lap("null refits")
    run.stage = "the polish"
    # the leaders fitted to convergence before their residuals are judged: a candidate fit
    # stops after a fixed budget, and one that stopped short of noise would send the case to
    # the wider search for nothing (confusion case 24: creep at 1.09 x noise after its budget)
    _polish_leader(pb, cal, refits)
    # and the null gets the same chance from where the polished leader's nominal values went
    cal, null_source = _null_refits(pb, nominal, cal, refits, NULL_REFITS)
    run.cal = cal
    clock.lap("polish")
    run.stage = "the wider search"
    searched_wide = False
    if not any(_explains(pb, r.candidate) for r in refits) and not _leaves_noise(pb, cal):
        # a systematic residual that no candidate fitted so far explains: the wider search
        # (a population search of every candidate's own, from the best null found so far)
        # before the answer may be "unexplained"
        refits = _wide_search(pb, cal, order, screened, refits)
        searched_wide = True
        before = cal.fit.chi2
        cal, null_source = _null_refits(pb, nominal, cal, refits, NULL_REFITS)
        if cal.fit.chi2 < 0.5 * before and not any(_explains(pb, r.candidate) for r in refits):
            # a candidate led the null to a far better basin of the nominal parameters: the
            # candidates start again from there (scored and fitted as in the first round)
            order, screened = _screen(pb, cal, nominal)
            again = _fit_candidates(pb, cal, order, screened, refit_top)
            refits = _better_of(refits, again)
            cal, null_source = _null_refits(pb, nominal, cal, refits, NULL_REFITS)
        _polish_leader(pb, cal, refits)
    if not cal.search.converged and not any(_explains(pb, r.candidate) for r in refits):
        # the calibration's local fits disagree and nothing explains the residual: a wrong
        # structure (a PE whose mass matters, modelled lumped) calibrates badly in the nominal
        # structure, and the structural candidate's fits start from that calibration; each
        # structural candidate gets a global calibration of its own
        run.stage = "the structural calibrations"
        refits = _structural_calibrations(pb, cal, nominal, refits)
        _polish_leader(pb, cal, refits)
    run.cal, run.refits = cal, refits
    clock.lap("wider search")
    run.stage = "the held-out prediction"
    ranking = _rank_with_heldout(refits, heldout)
    # the null's held-out prediction, for comparison, only where a candidate has one
    ho_cal = heldout.rms(cal.fit.spec, cal.at) if any(_finite(c.heldout_rms) for c in ranking) else math.nan
    clock.lap("held-out")
    locations, windows = locate(rec, cal.fit.residuals, pb.sigma)
    spans = merge_windows(windows, pb.sigma)

    verdict, reason, rms_after = _verdict(ranking, cal, noise, ho_cal, searched_wide)
    second: Optional[SecondSearch] = None
    lead = _partial_leader(pb, refits) if verdict in ("unexplained", "not_converged") else None
    if lead is not None:
        # one effect stands but leaves a systematic residual: a second one, from the model with it
        run.stage = "the second effect"
        second = _second_effect(pb, cal, lead, heldout, refits)
        if not second.named:
            # two effects that each mimic part of the other from the leader's optimum: the
            # supported candidates' pairs fitted together from their fits alone
            joint = _joint_pair(pb, cal, refits, heldout)
            if joint is not None and joint.named:
                second = joint
            elif joint is not None:
                second.reason += (f"; fitted jointly, {joint.first.effect} with "
                                  f"{joint.pair.effect if joint.pair else '-'}: {joint.reason}")
        if second.named and second.pair is not None:
            verdict, reason, rms_after = f"{second.first.effect}+{second.pair.effect}", second.reason, \
                second.pair.rms_after
        else:
            reason += f"; second effect: {second.reason}"
        clock.lap("second effect")
    found: Optional[Discovery] = None
    from_nominal = verdict == "not_converged"
    d_lead: Optional[_Refit] = None
    if discover and verdict in ("unexplained", "not_converged"):
        # beyond the catalogue: only where every catalogue effect left a systematic residual;
        # from the model with the first effect when one stands (what it leaves is what is missing).
        # After "not_converged" from the nominal values as given: a missing force leaves the null
        # several bad basins, each compensating for it its own way, and the force inferred from the
        # best of them is bent by that compensation (a quadratic drag on the main body: from the
        # calibration's best, 4.7 x noise, no form stood — RESULTS 15d; from the nominal values,
        # v1|v1| at the true coefficient, 1.00 x noise, held out 1.04 x — RESULTS 15e). The found
        # term's gain is then taken against the calibrated null too (_found_against_null).
        run.stage = "discovery"
        if not _finite(ho_cal):
            ho_cal = heldout.rms(cal.fit.spec, cal.at)
        d_spec, d_free, d_ho, d_lead = _discovery_start(verdict, lead, cal, nominal, ho_cal)
        try:
            found = run_discovery(rec, d_spec, d_free, pb.obj, heldout, d_ho, nominal=nominal.spec,
                                  progress=pb.tick)
        except DivergenceError as e:
            # a model the simulator cannot run through the inferred force: no discovery, said so
            reason += f"; discovery stopped: the simulator could not follow the inferred force ({e})"
        except (np.linalg.LinAlgError, NumericalFailure) as e:
            reason += f"; discovery stopped by a numerical failure, which says nothing about the physics: {e}"
        else:
            if found.discovered and d_lead is None:
                _found_against_null(pb, cal, found)
            if found.discovered and from_nominal:
                # its figures against the best calibrated null (discovery's own are against the
                # nominal values as given, far off when a force is missing)
                sigma = pb.sigma
                found.rms_before, found.heldout_rms_before = cal.fit.rms, ho_cal
                where = "main body" if found.body == "main" else "weight"
                terms = ", ".join(t.symbol for t in found.form.terms) if found.form is not None else ""
                found.reason = (f"the calibration did not converge ({cal.search.summary()}); discovery from the "
                                f"nominal values as given: a force on the {where} of the form {terms} "
                                f"({found.description}) improves BIC by {found.delta_bic:.0f} over the best calibrated "
                                f"null (RMS {cal.fit.rms / sigma:.2f} → {found.rms_after / sigma:.2f} x noise) and "
                                f"predicts the held-out experiment ({ho_cal * 1e9:.2f} → "
                                f"{found.heldout_rms_after * 1e9:.2f} nm)")
            if found.discovered:
                verdict, reason, rms_after = "discovered", found.reason, found.rms_after
                if d_lead is not None:
                    without, r0, lib = _without_lead(pb, cal, d_lead, found)
                    if without >= BIC_THRESHOLD:
                        verdict = f"{d_lead.candidate.effect}+discovered"
                        reason = (f"{d_lead.candidate.effect} stands but leaves a systematic residual; beyond it, "
                                  f"{reason}; {d_lead.candidate.effect} pays its own way beside the found term "
                                  f"(ΔBIC {without:.0f} against the term alone)")
                    else:
                        # the term alone is the answer: its own refit from the calibrated null
                        found.refit, found.rms_after = r0, r0.rms
                        found.values = {f.name: (r0.values[f.name], r0.std.get(f.name)) for f in lib}
                        found.delta_bic = cal.fit.chi2 - r0.chi2 - len(lib) * pb.ln_n
                        rms_after = r0.rms
                        reason = (f"{reason} (found from the model with {d_lead.candidate.effect}, which is not needed "
                                  f"beside it: ΔBIC {without:.0f} < {BIC_THRESHOLD:g} against the term alone, "
                                  f"refitted from the calibrated model: RMS {r0.rms / pb.sigma:.2f} x noise)")
            else:
                # d_lead is lead when set (_discovery_start)
                alone = _alone_explains(pb, cal, heldout, ho_cal, d_lead, found) if d_lead is not None else None
                if alone is not None:
                    found = alone
                    verdict, reason, rms_after = "discovered", found.reason, found.rms_after
                else:
                    reason += f"; discovery: {found.reason}"
        clock.lap("discovery")
    degenerate = near_degenerate(list(screened.values()))
    alternatives = _alternatives(ranking, verdict, degenerate)
    proposal: Optional[Proposal] = None
    if alternatives:
        reason += "; cannot be told apart from " + ", ".join(f"{a.effect} ({a.why})" for a in alternatives)
        run.stage = "the next experiment"
        proposal = _next_experiment(pb, refits, verdict, alternatives[0].effect)
        clock.lap("next experiment")
    parameter_proposal = _determining_experiment(pb, refits, verdict)
    if (parameter_proposal is None and verdict in ("unexplained", "not_converged") and found is not None
            and not found.discovered):
        run.stage = "the next experiment"
        parameter_proposal = _travel_experiment(pb, found)
    if parameter_proposal is not None:
        clock.lap("next experiment (parameter)")
    n_all = pb.obj.n
    return Diagnosis(
        case=rec.name, verdict=verdict, reason=reason, ranking=ranking, noise=noise,
        rms_before=math.sqrt(sum(float(np.sum(r * r)) for r in nominal.residuals) / n_all),
        rms_calibrated=cal.fit.rms, rms_after=rms_after,
        calibrated=cal.fit.values, calibrated_std=cal.fit.std, locations=locations, windows=spans,
        heldout_experiment=rec.experiments[heldout.index].name, heldout_rms_calibrated=ho_cal,
        whiteness_z_calibrated=cal.whiteness_z, seconds=time.perf_counter() - t_start, timings=clock.timings,
        simulations=sim.evaluations, recording=rec, nominal_residuals=nominal.residuals,
        calibrated_residuals=cal.fit.residuals, nominal_spec=nominal.spec, calibrated_spec=cal.fit.spec, simulator=sim,
        calibration_converged=cal.search.converged, calibration_summary=cal.search.summary(),
        calibration_chi2=[p.chi2 for p in cal.search.polishes], null_source=null_source,
        alternatives=alternatives,
        screening={k: v.delta_chi2 for k, v in sorted(screened.items(), key=lambda kv: -kv[1].delta_chi2)},
        degenerate_pairs=[list(p) for p in degenerate], searched_wide=searched_wide,
        calibration_multistart=cal.search.multistart.to_dict() if cal.search.multistart is not None else {},
        discovery=found, second=second, proposal=proposal, parameter_proposal=parameter_proposal,
    )


def _renoised(pb: _Problem, cal: _Calibration, noise: NoiseEstimate) -> tuple[_Problem, _Calibration]:
    """The problem and the calibration in units of a new noise floor (chi^2 scale as 1/sigma^2)."""
    if noise.sigma == pb.sigma:
        return replace(pb, noise=noise), cal
    f = (pb.sigma / noise.sigma) ** 2
    pb = _Problem(pb.rec, noise, pb.sim, Objective(pb.rec, pb.sim, noise.sigma), pb.tick)
    seen: set[int] = set()
    for r in [cal.fit, cal.one_cycle, *cal.search.polishes]:
        if id(r) in seen:
            continue
        seen.add(id(r))
        r.chi2 *= f
        if r.jac is not None:
            r.jac = r.jac * math.sqrt(f)
    cal.search.search_best *= f
    cal.bic = cal.fit.chi2 + (len(cal.free) + pb.n_offsets) * pb.ln_n
    return pb, cal


def _alternatives(ranking: list[Candidate], verdict: str, degenerate: list[tuple[str, str, float]]
                  ) -> list[Alternative]:
    """Effects the data cannot tell apart from the verdict's: a supported candidate within
    SEPARATION in ΔBIC of it, or one whose screening direction is near-parallel to it."""
    lead = next((c for c in ranking if c.effect == verdict), None)
    if lead is None:
        return []
    out: dict[str, Alternative] = {}
    for c in ranking:
        if c is lead or not _eligible(c):
            continue
        if lead.delta_bic - c.delta_bic < SEPARATION:
            out[c.effect] = Alternative(c.effect, c.delta_bic, f"ΔBIC {c.delta_bic:.0f} against the leader's "
                                        f"{lead.delta_bic:.0f}, within {SEPARATION:g}")
    for a, b, cos in degenerate:
        other = b if a == verdict else a if b == verdict else None
        if other is None or other in out:
            continue
        match = next((x for x in ranking if x.effect == other), None)
        if match is not None and _eligible(match):
            out[other] = Alternative(other, match.delta_bic,
                                     f"its signature is parallel to the leader's (|cos| = {cos:.3f})")
    return list(out.values())


def _verdict(ranking: list[Candidate], cal: _Calibration, noise: NoiseEstimate, ho_cal: float,
             searched_wide: bool = False) -> tuple[str, str, float]:
    """An effect is the verdict only if it was fitted over everything, is present (its
    likelihood-ratio test against the null rejects "no effect" at LR_ALPHA), improves BIC over the best null by
    BIC_THRESHOLD and leaves noise. Otherwise "none" when the null leaves noise — a white
    residual at the noise floor: "none" never stands while the whiteness test flags structure;
    else "not_converged" when the calibration's local fits did not reach one optimum (the tool's
    fit failed), else "unexplained" (after the wider search of every candidate)."""
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
                    f"(ΔBIC ≥ {BIC_THRESHOLD:g} and a likelihood-ratio test against 'no effect' at {LR_ALPHA:g})",
                    fit.rms)
        if not cal.search.converged:
            return ("not_converged", f"the calibration did not converge ({cal.search.summary()}) and a systematic "
                    f"residual remains ({residual}); no verdict on missing physics", fit.rms)
        wide = " (every candidate fitted, the wider search)" if searched_wide else ""
        return ("unexplained", f"a systematic residual remains after a converged calibration ({residual}) and "
                f"no catalogue effect explains it{wide}", fit.rms)
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
    ("screening", 6.0, 30.0),
    ("candidate fits", 34.0, 300.0),
    ("null refits", 6.0, 30.0),
    ("polish", 6.0, 30.0),
    ("wider search", 4.0, 300.0),
    ("held-out", 4.0, 10.0),
    # the stages that run only on some cases (a first effect leaving a systematic residual, an
    # unexplained residual, an alternative or an undetermined parameter): no share of the bar
    ("second effect", 0.0, 300.0),
    ("discovery", 0.0, 100.0),
    ("next experiment", 0.0, 50.0),
    ("next experiment (parameter)", 0.0, 50.0),
)


class _Progress:
    """A percent bar over the stages: each stage owns its share, simulations advance it within the
    stage (approaching the share's end, as a stage's length is not known in advance). The ETA is
    the average rate of the whole run so far (tqdm's smoothing 0), not the last few updates':
    a stage that runs long no longer sends it from minutes to an hour and back. Beside it: the
    stage and the simulated runs, counted as the report counts them (``runs()``, the
    simulator's own count, one per experiment simulated)."""

    def __init__(self, name: str, runs: Optional[Callable[[], int]] = None) -> None:
        from tqdm.auto import tqdm

        self.bar = tqdm(total=100.0, desc=f"diagnosing {name}", unit="%", smoothing=0.0,
                        bar_format="{desc}: {percentage:3.0f}%|{bar}| [{elapsed}<{remaining}{postfix}]")
        self.stage, self.start, self.in_stage, self.evals = 0, 0.0, 0.0, 0
        self.runs = runs
        self._show()

    def _show(self) -> None:
        name = STAGES[self.stage][0] if self.stage < len(STAGES) else "done"
        count = self.runs() if self.runs is not None else self.evals
        self.bar.set_postfix_str(f"{name}, {count} simulated runs", refresh=False)

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

    def close(self, done: bool = True) -> None:
        if done:
            self.bar.update(max(0.0, 100.0 - self.bar.n))
        self.bar.close()


def _bar(show: bool, name: str, runs: Optional[Callable[[], int]] = None) -> Optional[_Progress]:
    return _Progress(name, runs) if show else None
