"""The catalogue stages: the nominal model as given, its calibration, screening of every applicable
effect, each candidate's multistart fits (and the wider search), the null refitted from where
the candidates left the nominal parameters, the polish of the leaders, and the structural
candidates' own calibrations."""

from __future__ import annotations

import math
from dataclasses import replace
from typing import Any, Optional

import numpy as np

from ..core.batch import Structure
from ..core.declarations import GRAVITY
from .calibration import calibrate as global_calibration
from .calibration import search
from .case_model import ModelSpec
from .catalogue import CATALOGUE, Effect, EffectParam
from .fitting import FitResult, FreeParam, Objective, apply, fit, fit_progressive, set_effect
from .identifiability import assess
from .multistart import Start, agree, fit_at_noise, multistart
from .noise import NoiseEstimate
from .problem import CalibratedNull, Nominal, Problem, Refit, calibration_params
from .progress import part
from .results import Candidate
from .rules import by_rank, is_eligible
from .screening import Screened, screen
from .thresholds import (
    BIC_THRESHOLD,
    CALIBRATED,
    CANDIDATE_FITS,
    CANDIDATE_HORIZONS,
    CANDIDATE_MAGNITUDES,
    CANDIDATE_NFEV,
    CONTINUATION_HORIZONS,
    CONTINUATION_NFEV,
    MIN_SCORE,
    POLISH_CLOSE,
    POLISH_NFEV,
    SEPARATION,
    WIDE_FITS,
    WIDE_GENERATIONS,
    WIDE_POPULATION,
)
from .whiteness import whiteness_z


def nominal_model(pb: Problem) -> Nominal:
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
    return Nominal(structure, p0, spec, res, chi2)


def calibrate_null(pb: Problem, nominal: Nominal) -> CalibratedNull:
    """Calibrate the plausibly-off nominal parameters globally (see :mod:`.calibration`): a
    population search over their plausible ranges on the segmented misfit, then independent
    least-squares polishes over everything."""
    free = calibration_params(nominal.params)
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
    return CalibratedNull(free, one, one_at, cal, at, bic, whiteness_z(cal.residuals, pb.obj), g, scan_at)


def magnitudes(ep: EffectParam) -> list[float]:
    """An effect parameter's starting values, spanning its whole fit range: a log-scaled one (a
    time constant, the hysteresis loop's size) at its catalogue starts and a decade beyond the
    largest where that is inside its bounds; any other at half-decade multiples of its fit scale
    (CANDIDATE_MAGNITUDES, continued while inside its bounds; both signs where "no effect" lies
    inside them), and at "no effect". A start ladder that stopped at 30 x the scale never
    started a weight drag of 50 N s/m (scale 0.5) or an incline of 0.01 rad (scale 1e-4) near
    its value, and the fits from the ladder's top ended in another basin."""
    if ep.log:
        out = list(ep.starts)
        beyond = 10.0 * max(out)
        return out + ([beyond] if beyond < ep.upper else [])
    ladder = list(CANDIDATE_MAGNITUDES)
    while ladder[-1] * ep.scale < ep.upper - ep.lower:
        ladder.append(10.0 * ladder[-2])
    out = [ep.none]
    for m in ladder:
        for sign in (1.0, -1.0):
            v = ep.none + sign * m * ep.scale
            if ep.lower < v < ep.upper:  # a start on a bound would stay there
                out.append(v)
    return out


def candidate_starts(pb: Problem, cal: CalibratedNull, eff: Effect, sc: Optional[Screened]) -> list[Start]:
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
    grids = [magnitudes(ep) for ep in eff.params]
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


def screen_candidates(pb: Problem, cal: CalibratedNull, nominal: Nominal) -> tuple[list[Effect], dict[str, Screened]]:
    """Every applicable effect scored at the null optimum, best score first."""
    effects = [e for e in CATALOGUE if e.applies(nominal.structure, nominal.params)]
    screened = {s.effect.id: s for s in screen(pb.obj, cal.fit, cal.at, effects, pb.sigma, pb.tick)}
    return sorted(effects, key=lambda e: -screened[e.id].delta_chi2), screened


def fit_candidates(pb: Problem, cal: CalibratedNull, order: list[Effect], screened: dict[str, Screened],
                    refit_top: int, already: Optional[list[Refit]] = None, local_fits: int = CANDIDATE_FITS,
                    min_score: float = MIN_SCORE, sink: Optional[list[Refit]] = None) -> list[Refit]:
    """The `refit_top` best-scored effects (those scoring at least `min_score`) fitted by
    multistart over two cycles, then everything; the others reported with their score's
    linearised step only. A fit that ends no better than the null model it contains is
    reported at the null."""
    done = {r.candidate.effect: r for r in (already or []) if not r.candidate.screened_only}
    # each finished candidate goes straight into `sink` (kept if the run is interrupted)
    out: list[Refit] = sink if sink is not None else []
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
            c = make_candidate(pb, cal, eff, r, screened_only=True)
            c.score = sc.delta_chi2
            out.append(Refit(c, base, free))
            continue
        ms = multistart(pb.obj, base, candidate_starts(pb, cal, eff, sc), local_fits=local_fits,
                        horizons=CANDIDATE_HORIZONS, max_nfev=CANDIDATE_NFEV, always=("nominal values",),
                        stop_at_noise=True, progress=pb.tick)
        r = ms.best
        null = null_point(cal, eff, base)
        if null is not None and r.chi2 >= null.chi2:
            # every candidate contains the null model: its fit never ends worse than it
            c = make_candidate(pb, cal, eff, null, False, at_null=True)
            c.multistart = ms.to_dict()
            c.score = sc.delta_chi2
            out.append(Refit(c, base, [p.at(cal.fit.values[p.name]) if p.name in cal.fit.values else p for p in free]))
            continue
        c = make_candidate(pb, cal, eff, r, screened_only=False)
        c.multistart = ms.to_dict()
        c.score = sc.delta_chi2
        out.append(Refit(c, base, [p.at(r.values[p.name]) for p in free]))
    return out


def wide_search(pb: Problem, cal: CalibratedNull, order: list[Effect], screened: dict[str, Screened],
                 first: list[Refit]) -> list[Refit]:
    """:func:`_wide_search`, timed as the part "wide search"."""
    with part("wide search"):
        return _wide_search(pb, cal, order, screened, first)


def _wide_search(pb: Problem, cal: CalibratedNull, order: list[Effect], screened: dict[str, Screened],
                 first: list[Refit]) -> list[Refit]:
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
        start = list(cal.at) + [ep.free(magnitudes(ep)[1 if not ep.log and len(magnitudes(ep)) > 1 else 0])
                                for ep in eff.params]
        with part("population searches"):
            picks, best, _ = search(pb.obj, base, start, cycles=1, population_per_param=WIDE_POPULATION,
                                    generations=WIDE_GENERATIONS, progress=pb.tick)
        starts = [Start("population search best" if k == 0 else f"population search member {k + 1}",
                        [f.at(f.value(float(x))) for f, x in zip(start, u)], "population search best" if k == 0 else "")
                  for k, u in enumerate(picks)]
        prev = by_id.get(eff.id)
        if prev is not None and not prev.candidate.screened_only:
            starts.append(Start("first-round fit", list(prev.free), "first-round fit"))
        starts += [st for st in candidate_starts(pb, cal, eff, sc) if st.group in ("null fit", "nominal values")]
        searched.append((best, eff, starts))
    searched.sort(key=lambda x: x[0])
    out = {r.candidate.effect: r for r in first}
    for _, eff, starts in searched[:WIDE_FITS]:
        base = ModelSpec(eff.structure(cal.fit.spec.structure), dict(cal.fit.spec.params), dict(cal.fit.spec.effects))
        with part("multistart fits"):
            ms = multistart(pb.obj, base, starts, local_fits=1, horizons=(2, None), max_nfev=(10, 10),
                            always=("population search best", "null fit"), progress=pb.tick)
        r = ms.best
        old = out.get(eff.id)
        if old is not None and not old.candidate.screened_only and old.candidate.chi2 <= r.chi2:
            continue
        null = null_point(cal, eff, base)
        if null is not None and r.chi2 >= null.chi2:
            continue
        c = make_candidate(pb, cal, eff, r, screened_only=False)
        c.multistart = ms.to_dict()
        c.score = screened[eff.id].delta_chi2
        out[eff.id] = Refit(c, base, [p.at(r.values[p.name]) for p in starts[0].free])
    return list(out.values())


def make_candidate(pb: Problem, cal: CalibratedNull, eff: Effect, r: FitResult, screened_only: bool,
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
        whiteness_z(r.residuals, pb.obj), screened_only, r.residuals, r.spec,
        reported_std={n: s for n, (_, s) in reported.items() if s is not None},
        significance=significance, correlation=corr, at_null=at_null, lr_chi2=cal.fit.chi2 - r.chi2,
        identifiability=assess(r.values, r.std, r.corr, names + [n for n in cal.fit.values if n not in names]),
        calibrated_std={n: r.std[n] for n in CALIBRATED if n in r.std})


def null_point(cal: CalibratedNull, eff: Effect, base: ModelSpec) -> Optional[FitResult]:
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


def refit_nulls(pb: Problem, nominal: Nominal, cal: CalibratedNull, refits: list[Refit],
                  refit_top: int) -> tuple[CalibratedNull, str]:
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
            best = CalibratedNull(cal.free, n0, at, n0, at, bic, whiteness_z(n0.residuals, pb.obj), cal.search,
                                  cal.scan_at)
            source = f"nominal refit from the {c.effect} fit"
    for r in refits:
        against_null(pb, best, r)
    return best, source


def against_null(pb: Problem, null: CalibratedNull, r: Refit) -> None:
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
            at = null_point(null, eff, r.base)
            if at is not None:
                nc = make_candidate(pb, null, eff, at, False, at_null=True)
                nc.score, nc.multistart = c.score, c.multistart
                r.candidate = c = nc
                r.free = [p.at(null.fit.values[p.name]) if p.name in null.fit.values else p for p in r.free]
            c.at_null = True
    c.delta_bic = null.bic - c.bic
    c.lr_chi2 = null.fit.chi2 - c.chi2


def polish_leaders(pb: Problem, cal: CalibratedNull, refits: list[Refit]) -> None:
    """The leading supported candidate — and every supported one within SEPARATION of it in
    ΔBIC (at most POLISH_CLOSE in all) — fitted to convergence over everything from its optimum
    (the candidate fits stop after a fixed budget): their residuals are then judged, and close
    rivals compared, at their optima, not at the budget's."""
    eligible = [r for r in by_rank(refits) if is_eligible(r.candidate)]
    if not eligible:
        return
    lead_bic = eligible[0].candidate.delta_bic
    for r0 in [r for r in eligible if lead_bic - r.candidate.delta_bic < SEPARATION][:POLISH_CLOSE]:
        eff = next(e for e in CATALOGUE if e.id == r0.candidate.effect)
        spec = r0.candidate.spec
        assert spec is not None  # a fitted candidate has its model
        base = ModelSpec(r0.base.structure, dict(spec.params), dict(spec.effects))
        r = fit(pb.obj, base, r0.free, max_nfev=POLISH_NFEV, progress=pb.tick)
        r = continued(pb, cal, base, r0.free, r)
        if r.chi2 < r0.candidate.chi2:
            c = make_candidate(pb, cal, eff, r, screened_only=False)
            c.delta_bic = cal.bic - c.bic
            c.score, c.multistart = r0.candidate.score, r0.candidate.multistart
            r0.candidate = c
            r0.free = [p.at(r.values[p.name]) for p in r0.free]


def continued(pb: Problem, cal: CalibratedNull, base: ModelSpec, free: list[FreeParam], r: FitResult) -> FitResult:
    """A leader's fit `r` that leaves structure, fitted again over CONTINUATION_HORIZONS (the
    first drive cycle, then everything) from the nominal values as given and from the null fit,
    its effect parameters at their fitted values; the best of them. Least squares over the whole
    record at once can slide into a basin the first cycle alone does not have (RESULTS §39)."""
    if fit_at_noise(r):
        return r
    best = r
    for at in (cal.free, cal.at):
        calibrated = {f.name: f for f in at}
        start = [calibrated.get(p.name) or p.at(r.values[p.name]) for p in free]
        r2 = fit_progressive(pb.obj, base, start, horizons=CONTINUATION_HORIZONS, max_nfev=CONTINUATION_NFEV,
                             progress=pb.tick)
        if r2.chi2 < best.chi2:
            best = r2
        if fit_at_noise(best):
            break
    return best


def structural_calibrations(pb: Problem, cal: CalibratedNull, nominal: Nominal, refits: list[Refit]
                             ) -> list[Refit]:
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
        c = make_candidate(pb, cal, eff, r, screened_only=False)
        c.multistart = g.multistart.to_dict() if g.multistart is not None else {}
        if old is not None:
            c.score = old.candidate.score
        out[eff.id] = Refit(c, base, [f.at(r.values[f.name]) for f in cal.free])
    return list(out.values())


def renoised(pb: Problem, cal: CalibratedNull, noise: NoiseEstimate) -> tuple[Problem, CalibratedNull]:
    """The problem and the calibration in units of a new noise floor (chi^2 scale as 1/sigma^2)."""
    if noise.sigma == pb.sigma:
        return replace(pb, noise=noise), cal
    f = (pb.sigma / noise.sigma) ** 2
    pb = Problem(pb.rec, noise, pb.sim, Objective(pb.rec, pb.sim, noise.sigma), pb.tick)
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
