"""The measurement taken into the fits. After the calibration: the noise model learned from the
recording and the calibrated prediction (:func:`.noise_model.learn`); the recording cleaned of
its spikes and every fit made in the noise colour's whitened metric (the null refitted there from
its optimum, its other optima re-scored). At the verdict: hum lines, a zero drifting in each file
and a late channel are measurement properties where the calibrated null with them leaves noise
as well as the verdict's model does (:func:`artefacts_instead`; a delay against its look-alike
lag by Vuong's test, :mod:`.closer`) — a missing effect can put a
sinusoid's share, a trend or a lag into a residual too, so they are weighed against the physics
rather than taken before it."""

from __future__ import annotations

import math
from dataclasses import replace
from typing import Callable, Optional

import numpy as np
from numpy.typing import NDArray

from ..io.recording import Recording
from .candidates import calibrate_null
from .case_model import ModelSpec
from .closer import contest
from .fitting import Objective, apply, fit
from .measurement import Measurement, Whitener
from .noise import NoiseEstimate
from .noise_model import (
    Learned,
    Residuals,
    delay_significant,
    find_delay,
    find_drift,
    find_lines,
    fit_colour,
    learn,
    relearn,
    slopes_differ,
)
from .problem import CalibratedNull, Nominal, Problem
from .rules import null_leaves_noise
from .thresholds import (
    CLOSER_FITS_Z,
    CLOSER_LAGS,
    CLOSER_Z,
    DELAY_PROGRESS,
    DELAY_ROUNDS,
    DELAY_TOL_S,
    RECOLOUR_SIGMAS,
    REMEASURE_NFEV,
    REPEAT_Z,
    SEPARATION,
)
from .whiteness import whiteness_z

#: the catalogue effect that is a drift of the reading at one rate for every file
COMMON_DRIFT_EFFECT = "thermal_drift"


def remeasured(pb: Problem, cal: CalibratedNull, nominal: Nominal, noise: NoiseEstimate
               ) -> tuple[Problem, CalibratedNull, NoiseEstimate, Learned]:
    """(problem, calibrated null, noise, what was learned) in the noise colour's metric, the
    spikes rejected; the inputs unchanged (bit for bit) where the recording is white and clean."""
    preds = pb.sim.predict([cal.fit.spec])[0]
    found = learn(pb.rec, preds, noise.sigma, _jacobians(pb, cal, nominal, noise))
    noise = replace(_noise_of(noise, found), model=found.model)
    if found.measurement.trivial and not found.model.outliers:
        return pb, cal, noise, found  # the white path as it was
    pb2, cal2 = _refit(pb, cal, nominal, noise, found.rec, found.measurement)
    return pb2, cal2, noise, found


def relearned(pb: Problem, cal: CalibratedNull, nominal: Nominal, noise: NoiseEstimate, found: Learned) -> Learned:
    """The hum, a drifting zero and a delay tested again against the null `cal` (refitted since
    the calibration from the candidates' optima), on the recording as the fits take it."""
    preds = pb.sim.predict([cal.fit.spec])[0]
    return relearn(pb.rec, preds, noise.sigma, found, _jacobians(pb, cal, nominal, noise))


def drift_beside(pb: Problem, cal: CalibratedNull, nominal: Nominal, noise: NoiseEstimate, found: Learned,
                 spec: ModelSpec) -> bool:
    """Whether the files' slopes still differ beyond one common slope on the residual of `spec`, a
    model with a drift rate common to every file (the catalogue's thermal drift), its hum and
    delay as found (the rest's check of :func:`find_drift` was passed on the null's residual).
    Per-file slopes beyond one common slope on the null's residual can be the null's misfit beside
    a common drift (a thermal drift under spikes with m1 and the presliding stiffness mis-set:
    -95, -103, -128 nm per file), which the model with the rate and its own refitted values takes
    up; then the per-file zeros are nf parameters where one rate does, and they are not weighed
    against it. The calibrated parameters' Jacobian at the null's optimum is projected off the
    slopes, as on the null's residual."""
    preds = pb.sim.predict([spec])[0]
    jac = _jacobians(pb, cal, nominal, noise)
    res = Residuals.of(pb.rec, preds, lambda m: jac(pb.rec, m))
    delay = found.delay_s if delay_significant(found.delay_gain, found.delay_s) else 0.0
    m = replace(found.measurement, lines_Hz=found.lines_Hz, drift=False).with_delay(delay)
    return slopes_differ(res, m, noise.sigma)


def artefacts_instead(pb: Problem, cal: CalibratedNull, nominal: Nominal, noise: NoiseEstimate, found: Learned,
                      lead_chi2: float, lead: Optional[dict[str, float]] = None,
                      lead_spec: Optional[ModelSpec] = None) -> Optional[tuple[Problem, CalibratedNull, NoiseEstimate]]:
    """Where hum lines, a drifting zero or a channel delay were found and the calibrated null with
    them (the delay and the null estimated in turn) leaves noise within SEPARATION of the chi^2 of
    the verdict's model (`lead_chi2`; inf for a verdict without one), or with a delay where the
    verdict's model is no closer than the noise's spread allows (:func:`_lead_closer`; a delay
    and a sensor lag have as many parameters), they explain what the
    verdict blamed on physics: (problem, null, noise) with them; else None (the noise model keeps
    them as found, not taken). `lead`: the leading candidate's nominal values, a second start
    (a lag candidate's fit bent them as the delay needs; the calibration bent them the other
    way), taken where it starts lower; `lead_spec`: the verdict's model, compared again in the
    colour refitted to the null's residual (:func:`_recoloured`) where the noise is coloured."""
    if not found.weighable:
        return None
    base = replace(found.measurement, lines_Hz=found.lines_Hz, drift=found.drift)
    delay = delay_significant(found.delay_gain, found.delay_s)
    start = _better_start(pb, cal, nominal, noise, base.with_delay(found.delay_s if delay else 0.0), lead)
    hidden: tuple[tuple[float, float], ...] = ()
    if delay:
        tau, pb2, cal2, base, hidden = _with_delay(pb, start, nominal, noise, base, found.delay_s)
    else:
        tau = 0.0
        pb2, cal2 = _refit(pb, start, nominal, noise, pb.rec, base)
    explains = null_leaves_noise(pb2, cal2) and (cal2.fit.chi2 <= lead_chi2 + SEPARATION or (
        delay and lead_spec is not None and not _lead_closer(pb, pb2, cal2, lead_spec)))
    if not explains and pb2.rec.measurement is not None and pb2.rec.measurement.whiten.order > 0:
        # in the rest's colour the null does not explain it; the colour read off the null's
        # residual may (a short rest misreads a strong colour). Where that colour disagrees with
        # the rest's, no rescue: 1/f noise reads stronger and louder over a whole file than
        # over a detrended 2 ms rest, and so does a residual that holds a missing effect
        recoloured = _recoloured(pb, pb2, cal2, noise, lead_spec)
        if recoloured is None:
            return None
        pb2, cal2, lead_chi2, noise = recoloured
        explains = null_leaves_noise(pb2, cal2) and cal2.fit.chi2 <= lead_chi2 + SEPARATION
    if not explains:
        return None
    model = noise.model
    if model is not None:
        notes = [n for n in model.notes if "drifts alike" not in n]
        if base.drift and not model.drift_m:
            notes.append("a zero drifting within each file, hidden while the null mimicked the delay, is "
                         "profiled out of every fit with it")
        if hidden:
            notes.append("a hum, hidden while the null mimicked the delay, is profiled out of every fit with it")
            model = replace(model, lines=hidden)
        if delay:
            notes.append("a channel delay and a first-order lag (sensor_lowpass, amplifier_lowpass) differ only "
                         "in the ringing's amplitude: the delay explains the residual as well")
        if base.drift:
            notes.append("a zero drifting within each file is profiled out of every fit: the catalogue's "
                         "thermal drift (one rate for every file) cannot be told from it")
        model = replace(model, delay_s=tau if delay else model.delay_s, delay_applied=delay,
                        artefacts_applied=True, notes=tuple(notes))
    return pb2, cal2, replace(noise, model=model)


def _lead_closer(pb: Problem, pb2: Problem, cal2: CalibratedNull, lead_spec: ModelSpec) -> bool:
    """Whether the data choose the verdict's model (`lead_spec`, fitted over `pb`) over the null
    with the delay (`cal2` over `pb2`) beyond the noise (:meth:`.closer.Contest.b_stands`): a
    delay and a first-order lag of the same size differ only in the ringing, and a coarse
    reading's rounding error can favour either by tens of chi^2."""
    v_lead = pb.obj.vector(pb.obj.predict([lead_spec])[0])
    v_null = pb2.obj.vector(pb2.obj.predict([cal2.fit.spec])[0])
    if v_lead.shape != v_null.shape or not (np.all(np.isfinite(v_lead)) and np.all(np.isfinite(v_null))):
        return True
    c = contest(v_null, v_lead, CLOSER_LAGS)
    return c.gain > SEPARATION and (not math.isfinite(c.spread) or c.b_stands(CLOSER_Z, CLOSER_FITS_Z))


def _recoloured(pb: Problem, pb2: Problem, cal2: CalibratedNull, noise: NoiseEstimate,
                lead_spec: Optional[ModelSpec]) -> Optional[tuple[Problem, CalibratedNull, float, NoiseEstimate]]:
    """The colour estimated again, from the residual of the null with the artefacts (thousands of
    samples where the rest has a few hundred: a lag-1 0.84 read 0.78 from 600 rest samples leaves
    the whitened residual a lag-1 correlation of 0.07, a whiteness z of 5 over 5,600 samples), and
    the null and the verdict's model (`lead_spec`) scored in it: (problem, null, the verdict's
    chi^2, the noise with the residual's level) there. None where the null does not run, or where
    the residual's colour or level disagrees with the rest's (a residual that holds a missing
    effect). Scored, not refitted: both keep the parameters they were fitted with."""
    m = pb2.rec.measurement
    assert m is not None
    plain = Objective(replace(pb2.rec, measurement=replace(m, whiten=Whitener(((),), (1.0,)))), pb2.sim, noise.sigma)
    pred = pb2.obj.predict([cal2.fit.spec])[0]
    res, _ = plain.profiled(pred)
    if not all(np.all(np.isfinite(r)) for r in res):
        return None
    colour = fit_colour(res)
    if colour is None or colour.rho.size < 2:
        return None
    agrees = _agrees(colour.rho, m.whiten, pb.rec) and abs(colour.sigma / noise.sigma - 1.0) <= (
        RECOLOUR_SIGMAS * _level_uncertainty(pb.rec, _lag1(m.whiten)))
    m2 = replace(m, whiten=Whitener.from_acf(colour.rho, colour.rho.size - 1))
    rec2 = replace(pb2.rec, measurement=m2)
    # the level with the colour: a 600-sample rest read a lag-1 0.84 noise of 1.46 nm as 1.31 nm
    noise = replace(noise, sigma=colour.sigma, source="the calibrated residual (coloured)")
    if noise.model is not None:
        note = () if agrees else ("the colour read off the whole residual is stronger than the rest's (1/f noise "
                                  "reads so over a whole file); it does not repeat with the drive",)
        noise = replace(noise, model=replace(noise.model, order=int(colour.rho.size - 1), lag1=float(colour.rho[1]),
                                             rho=tuple(float(v) for v in colour.rho),
                                             notes=noise.model.notes + note))
    noise = synced(noise)
    pb3 = Problem(rec2, noise, pb2.sim, Objective(rec2, pb2.sim, noise.sigma), pb2.tick)
    r3, _ = pb3.obj.profiled(pred)
    if not agrees and not repeats_z(pb.rec, [x / noise.sigma for x in r3]) <= REPEAT_Z:
        return None  # stronger and louder than the rest's, and repeating with the drive: an effect
    chi2 = float(sum(float((x * x).sum()) for x in r3)) / noise.sigma**2
    fit3 = replace(cal2.fit, residuals=r3, chi2=chi2, jac=None)
    bic = chi2 + (len(cal2.free) + pb3.n_offsets) * pb3.ln_n
    cal3 = replace(cal2, fit=fit3, bic=bic, whiteness_z=whiteness_z(r3, pb3.obj))
    lead_chi2 = math.inf
    if lead_spec is not None:
        rec_l = replace(pb.rec, measurement=replace(Measurement(), whiten=m2.whiten))
        obj_l = Objective(rec_l, pb.sim, noise.sigma)
        v = obj_l.vector(obj_l.predict([lead_spec])[0])
        lead_chi2 = float(v @ v)
    return pb3, cal3, lead_chi2, noise


def _rest_samples(rec: Recording) -> int:
    return sum(int(e.rest_mask.sum()) for e in rec.experiments)


def _level_uncertainty(rec: Recording, lag1: float) -> float:
    """Relative 1-sigma error of a correlated noise's level read off the rests (their effective
    sample size n (1 - rho) / (1 + rho))."""
    n = _rest_samples(rec)
    return 1.0 / math.sqrt(2.0 * max(n * (1.0 - lag1) / (1.0 + lag1), 2.0))


def _lag1(w: Whitener) -> float:
    """The lag-1 autocorrelation of a whitener's noise (its order-1 predictor's coefficient)."""
    return w.partial[1][0] if w.order >= 1 else 0.0


def _agrees(rho: NDArray[np.float64], rest: Whitener, rec: Recording) -> bool:
    """The colour read off a residual agrees with the rest's (lag-1 within RECOLOUR_SIGMAS of the
    rest estimate's standard error): a residual that still holds a missing effect reads a far
    stronger correlation (its smooth part), and a colour fitted to it would whiten the effect
    away."""
    r_rest = _lag1(rest)
    se = math.sqrt(max(1.0 - r_rest * r_rest, 1e-6) / max(_rest_samples(rec), 1))
    return abs(float(rho[1]) - r_rest) <= RECOLOUR_SIGMAS * se


def _better_start(pb: Problem, cal: CalibratedNull, nominal: Nominal, noise: NoiseEstimate, m: Measurement,
                  lead: Optional[dict[str, float]]) -> CalibratedNull:
    """`cal`, or `cal` centred on the nominal values `lead` where those fit better in the metric
    of `m` (two runs)."""
    if not lead or any(f.name not in lead for f in cal.free):
        return cal
    at = [f.at(lead[f.name]) for f in cal.free]
    obj = Objective(replace(pb.rec, measurement=None if m.trivial else m), pb.sim, noise.sigma)
    a, b = obj.predict([apply(nominal.spec, cal.at, np.zeros(len(at))), apply(nominal.spec, at, np.zeros(len(at)))])
    chi_a, chi_b = (float(v @ v) for v in (obj.vector(a), obj.vector(b)))
    return replace(cal, at=at) if chi_b < chi_a else cal


def _with_delay(pb: Problem, cal: CalibratedNull, nominal: Nominal, noise: NoiseEstimate, base: Measurement,
                tau: float) -> tuple[float, Problem, CalibratedNull, Measurement, tuple[tuple[float, float], ...]]:
    """The delay and the null estimated in turn (:func:`_delay_rounds`); where that null does not
    leave noise, the calibration run again with the delay (its global search, from the delay
    reached) and the rounds again from its optimum, the better null taken. A calibration without
    the delay can bend into a basin of its own: an LPS read 19.2 us late, m1, d33 and the
    presliding stiffness mis-set, calibrated to 17.4 x noise with the presliding damping at its
    bounds, and the rounds from there stopped at 13.6 us and 7.7 x noise."""
    out = _delay_rounds(pb, cal, nominal, noise, base, tau)
    if null_leaves_noise(out[1], out[2]) is not False:
        return out
    again = _delay_rounds(pb, calibrate_null(out[1], nominal), nominal, noise, base, out[0])
    return again if again[2].fit.chi2 < out[2].fit.chi2 else out


def _delay_rounds(pb: Problem, cal: CalibratedNull, nominal: Nominal, noise: NoiseEstimate, base: Measurement,
                  tau: float) -> tuple[float, Problem, CalibratedNull, Measurement, tuple[tuple[float, float], ...]]:
    """The delay and the null's parameters estimated in turn from `tau` [s] until the delay
    settles (DELAY_TOL_S): a calibration that ran without the delay bent its parameters to mimic
    part of it, and the delay scanned on that prediction comes out short of the truth (a 10 us
    delay: 6.8, 9.1, 9.7, 9.9 us round by round). A zero drifting in each file and a hum, hidden
    while the null mimicked the delay (a 9 us delay left the calibrated null at 16 x noise, and
    a 1.9 nm hum's amplitudes disagreed between files in that residual), are tested each round,
    and again at the settled delay (one taken on the way that the settled null no longer shows
    is dropped). Returns (delay, problem, null, the measurement without the delay, the hum lines
    found on the way: (frequency [Hz], amplitude [m]), () if none)."""
    pb2, cal2, m = pb, cal, base
    lines: tuple[tuple[float, float], ...] = ()
    for k in range(DELAY_ROUNDS):
        before = cal2.fit.chi2
        pb2, cal2 = _refit(pb, cal2, nominal, noise, pb.rec, m.with_delay(tau))
        if k and cal2.fit.chi2 > DELAY_PROGRESS * before and null_leaves_noise(pb2, cal2) is False:
            break  # the delay does not explain the residual: no use going on
        res = _residuals(pb, cal2, nominal, noise)
        new = find_delay(res, replace(m, drift=False), noise.sigma)[0]
        if not base.lines_Hz:
            lines = find_lines(res, replace(m, lines_Hz=(), drift=False).with_delay(new), noise.sigma) or lines
            m = replace(m, lines_Hz=tuple(f for f, _ in lines))
        m = replace(m, drift=m.drift or find_drift(res, replace(m, drift=False).with_delay(new), noise.sigma)[0])
        settled = abs(new - tau) < DELAY_TOL_S
        tau = new
        if settled:
            break
    if (m.drift and not base.drift) or lines:
        res = _residuals(pb, cal2, nominal, noise)
        if lines:
            lines = find_lines(res, replace(m, lines_Hz=(), drift=False).with_delay(tau), noise.sigma)
            m = replace(m, lines_Hz=tuple(f for f, _ in lines))
        if m.drift and not base.drift and not find_drift(res, replace(m, drift=False).with_delay(tau), noise.sigma)[0]:
            m = replace(m, drift=False)
    pb2, cal2 = _refit(pb, cal2, nominal, noise, pb.rec, m.with_delay(tau))
    return tau, pb2, cal2, m, lines


def _residuals(pb: Problem, cal2: CalibratedNull, nominal: Nominal, noise: NoiseEstimate) -> Residuals:
    """The residuals of the null `cal2` over `pb`'s recording, with its Jacobians."""
    # the prediction undelayed, the delay (as the scans take it) interpolated: the Jacobians in the
    # same terms, on pb's simulator
    jac = _jacobians(replace(pb, rec=replace(pb.rec, measurement=None)), cal2, nominal, noise)
    return Residuals.of(pb.rec, pb.sim.predict([cal2.fit.spec])[0], _bound(jac, pb.rec))


def _bound(jac: Callable[[Recording, Measurement], Optional[NDArray[np.float64]]], rec: Recording
           ) -> Callable[[Measurement], Optional[NDArray[np.float64]]]:
    return lambda m: jac(rec, m)


def _jacobians(pb: Problem, cal: CalibratedNull, nominal: Nominal, noise: NoiseEstimate
               ) -> Callable[[Recording, Measurement], Optional[NDArray[np.float64]]]:
    """The calibrated parameters' Jacobian at the null's optimum in a measurement's metric (the
    fit's own in the metric it was fitted in; one sensitivity run per other metric, remembered).
    It does not depend on the data, only on the model and the metric."""
    memo: dict[Measurement, Optional[NDArray[np.float64]]] = {}
    fitted_in = pb.rec.measurement or Measurement()

    def jac(rec: Recording, m: Measurement) -> Optional[NDArray[np.float64]]:
        if m == fitted_in and cal.fit.jac is not None:
            return cal.fit.jac
        if m not in memo:
            obj = Objective(replace(rec, measurement=m), pb.sim, noise.sigma)
            memo[m] = obj.jacobian(nominal.spec, cal.at, np.zeros(len(cal.at)))[1]
        return memo[m]
    return jac


def synced(noise: NoiseEstimate) -> NoiseEstimate:
    """The noise with its model's stated level set to the level every fit uses (the rest's
    estimate is cross-checked against the residual after the model is learned: a spike in a
    2 ms rest doubles the rest's RMS, the residual's, spikes rejected, does not)."""
    return replace(noise, model=replace(noise.model, sigma=noise.sigma)) if noise.model is not None else noise


def _noise_of(noise: NoiseEstimate, found: Learned) -> NoiseEstimate:
    """The noise estimate with the colour's level where the rest shows a colour (its relative
    uncertainty from the effective sample size of a correlated noise)."""
    m = found.model
    if not m.coloured or noise.source == "given":
        return noise
    return replace(noise, sigma=m.sigma, rest_sigma=m.sigma, relative_uncertainty=_level_uncertainty(found.rec, m.lag1),
                   source="rest (coloured)")


def repeats_z(rec: Recording, w: list[NDArray[np.float64]]) -> float:
    """How much a residual repeats from one drive cycle to the next: the sum over every pair of
    cycles of a file (sawtooth drives: whole periods after the rest) of the inner product of the
    whitened residual `w` (noise units, per experiment) over the pair, each divided by the root
    of the cycle's samples, over the root of the number of pairs. N(0, 1) for white noise of unit
    variance; large and positive for a missing effect (deterministic: it repeats with the drive).
    NaN where no file has two whole cycles."""
    total, pairs = 0.0, 0
    for e, r in zip(rec.experiments, w):
        if e.is_sampled or e.cycles < 2 or not e.frequency_Hz > 0:
            continue
        n = int(round(rec.sample_rate_Hz / e.frequency_Hz))
        s0 = int(round(e.rest_s * rec.sample_rate_Hz))
        cycles = [r[s0 + k * n: s0 + (k + 1) * n] for k in range(e.cycles)]
        cycles = [c for c in cycles if c.size == n and np.all(np.isfinite(c))]
        for a in range(len(cycles)):
            for b in range(a + 1, len(cycles)):
                total += float(cycles[a] @ cycles[b]) / math.sqrt(n)
                pairs += 1
    return total / math.sqrt(pairs) if pairs else math.nan


def _refit(pb: Problem, cal: CalibratedNull, nominal: Nominal, noise: NoiseEstimate, rec: Recording,
           m: Measurement) -> tuple[Problem, CalibratedNull]:
    """The null refitted from its optimum in the metric of `m` over `rec`, the calibration's other
    optima re-scored there (new records: `cal` is left as it was). A delay is simulated (the
    drive felt that late: :meth:`.case_model.CaseSimulator.late`), not interpolated."""
    sim = pb.sim.late(m.delay_s) if m.delay_s else pb.sim
    m = m.with_delay(0.0)
    rec = replace(rec, measurement=None if m.trivial else m)
    pb2 = Problem(rec, noise, sim, Objective(rec, sim, noise.sigma), pb.tick)
    r = fit(pb2.obj, nominal.spec, cal.at, max_nfev=REMEASURE_NFEV, progress=pb.tick)
    others = [p for p in cal.search.polishes if p is not cal.fit]
    rescored = []
    if others:  # one batch run
        for p, pr in zip(others, pb2.obj.predict([p.spec for p in others])):
            res, offs = pb2.obj.profiled(pr)
            rescored.append(replace(p, residuals=res, offsets=offs, jac=None,
                                    chi2=float(sum(float((x * x).sum()) for x in res)) / noise.sigma**2))
    polishes = sorted([r] + rescored, key=lambda p: p.chi2)
    best = polishes[0]
    one = replace(cal.one_cycle, chi2=pb2.obj.with_cycles(1).chi2(cal.one_cycle.spec))
    search = replace(cal.search, polishes=polishes, search_best=one.chi2, fit=best)
    at = [f.at(best.values[f.name]) for f in cal.free]
    bic = best.chi2 + (len(cal.free) + pb2.n_offsets) * pb2.ln_n
    wz = whiteness_z(best.residuals, pb2.obj)
    return pb2, CalibratedNull(cal.free, one, cal.one_cycle_at, best, at, bic, wz, search, cal.scan_at)
