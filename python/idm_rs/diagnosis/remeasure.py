"""The calibrated null taken into the measurement's metric: the noise model learned from the
recording and the calibrated prediction (:func:`.noise_model.learn`), the null refitted from its
optimum by generalised least squares, its other optima re-scored there. A zero drift is a
measurement property only where the null with it leaves noise (a missing effect can put a trend
into a residual too, and then it is the effect's to explain); a channel delay is weighed against
the verdict (:func:`delay_instead`): a first-order lag looks like a delay to first order."""

from __future__ import annotations

import math
from dataclasses import replace
from typing import Callable, Optional

import numpy as np
from numpy.typing import NDArray

from .fitting import Objective, fit
from .noise import NoiseEstimate, whiteness_z
from ..recording import Recording
from .measurement import Measurement
from .noise_model import Learned, Residuals, delay_significant, find_delay, learn
from .problem import CalibratedNull, Nominal, Problem
from .rules import null_leaves_noise
from .thresholds import DELAY_PROGRESS, DELAY_ROUNDS, REMEASURE_NFEV, SEPARATION


def remeasured(pb: Problem, cal: CalibratedNull, nominal: Nominal, noise: NoiseEstimate
               ) -> tuple[Problem, CalibratedNull, NoiseEstimate, Learned]:
    """(problem, calibrated null, noise, what was learned) in the measurement's metric; the
    inputs unchanged (bit for bit) where the recording is white, clean, without hum or drift."""
    preds = pb.sim.predict([cal.fit.spec])[0]
    found = learn(pb.rec, preds, noise.sigma, _jacobians(pb, cal, nominal, noise))
    model = found.model
    if found.measurement.trivial and not model.outliers and not found.drift:
        return pb, cal, replace(noise, model=model), found
    noise = _noise_of(noise, found)
    m_base = found.measurement
    notes = list(model.notes)
    refit: Optional[tuple[Problem, CalibratedNull]] = None
    if found.drift:
        pb2, cal2 = _refit(pb, cal, nominal, noise, found.rec, replace(m_base, drift=True))
        if null_leaves_noise(pb2, cal2):
            refit = pb2, cal2
            notes.append("a zero drifting within each file is profiled out of every fit: the catalogue's thermal "
                         "drift (one rate for every file) cannot be told from it")
        else:
            notes.append("a zero drift within each file estimated and not taken as a measurement property: the "
                         "calibrated model with it still leaves a systematic residual")
            model = replace(model, drift_m=())
    model = replace(model, notes=tuple(notes))
    if refit is None and m_base.trivial and not model.outliers:
        return pb, cal, replace(noise, model=model), found  # nothing taken on: the white path as it was
    pb2, cal2 = refit if refit is not None else _refit(pb, cal, nominal, noise, found.rec, m_base)
    found.measurement = pb2.rec.measurement or m_base
    return pb2, cal2, replace(noise, model=model), found


def delay_instead(pb: Problem, cal: CalibratedNull, nominal: Nominal, noise: NoiseEstimate, found: Learned,
                  lead_chi2: float) -> tuple[Problem, CalibratedNull, NoiseEstimate] | None:
    """Where the channel delay is significant and the calibrated null read that late leaves noise
    within SEPARATION of the chi^2 of the verdict's model (`lead_chi2`; inf for a verdict without
    one), the delay explains what the verdict blamed on physics: (problem, null, noise) with it;
    else None (the estimate stays in the noise model as a note)."""
    if not delay_significant(found.delay_gain):
        return None
    base = found.measurement or Measurement()
    tau, pb2, cal2 = found.delay_s, pb, cal
    # the delay and the null's parameters estimated in turn: a calibration that ran without the
    # delay bent its parameters to mimic part of it, and the delay scanned on that prediction
    # comes out short of the truth (a 10 us delay: 6.8, 9.1, 9.7, 9.9 us in four rounds)
    for _ in range(DELAY_ROUNDS):
        before = cal2.fit.chi2
        pb2, cal2 = _refit(pb, cal2, nominal, noise, pb.rec, base.with_delay(tau))
        if null_leaves_noise(pb2, cal2) or cal2.fit.chi2 > DELAY_PROGRESS * before:
            break
        res = Residuals.of(pb.rec, pb.sim.predict([cal2.fit.spec])[0])
        tau = find_delay(res, base, noise.sigma)[0]
    if not (null_leaves_noise(pb2, cal2) and cal2.fit.chi2 <= lead_chi2 + SEPARATION):
        return None
    found.delay_s = tau
    model = noise.model
    note = ("a channel delay and a first-order lag (sensor_lowpass, amplifier_lowpass) differ only in the "
            "ringing's amplitude: the delay explains the residual as well")
    if model is not None:
        # a delay puts a trend common to every file into the residual: not a drift then
        kept = tuple(n for n in model.notes if "drifts alike" not in n)
        model = replace(model, delay_s=tau, delay_applied=True, notes=kept + (note,))
    return pb2, cal2, replace(noise, model=model)


def _jacobians(pb: Problem, cal: CalibratedNull, nominal: Nominal, noise: NoiseEstimate
               ) -> Callable[[Recording, Measurement], Optional[NDArray[np.float64]]]:
    """The calibrated parameters' Jacobian at the null's optimum in a measurement's metric (the
    fit's own in the white one; one sensitivity run per other metric, remembered). It does not
    depend on the data, only on the model and the metric."""
    memo: dict[Measurement, Optional[NDArray[np.float64]]] = {}

    def jac(rec: Recording, m: Measurement) -> Optional[NDArray[np.float64]]:
        if m.trivial and cal.fit.jac is not None:
            return cal.fit.jac
        if m not in memo:
            obj = Objective(replace(rec, measurement=m), pb.sim, noise.sigma)
            memo[m] = obj.jacobian(nominal.spec, cal.at, np.zeros(len(cal.at)))[1]
        return memo[m]
    return jac


def _noise_of(noise: NoiseEstimate, found: Learned) -> NoiseEstimate:
    """The noise estimate with the colour's level where the rest shows a colour (its relative
    uncertainty from the effective sample size of a correlated noise)."""
    m = found.model
    if not m.coloured or noise.source == "given":
        return noise
    n = sum(int(e.rest_mask.sum()) for e in found.rec.experiments)
    n_eff = max(n * (1.0 - m.lag1) / (1.0 + m.lag1), 2.0)
    return replace(noise, sigma=m.sigma, rest_sigma=m.sigma, relative_uncertainty=1.0 / math.sqrt(2.0 * n_eff),
                   source="rest (coloured)")


def _refit(pb: Problem, cal: CalibratedNull, nominal: Nominal, noise: NoiseEstimate, rec: Recording,
           m: Measurement) -> tuple[Problem, CalibratedNull]:
    """The null refitted from its optimum in the metric of `m` over `rec`, the calibration's other
    optima re-scored there (new records: `cal` is left as it was)."""
    rec = replace(rec, measurement=None if m.trivial else m)
    pb2 = Problem(rec, noise, pb.sim, Objective(rec, pb.sim, noise.sigma), pb.tick)
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
    return pb2, CalibratedNull(cal.free, one, cal.one_cycle_at, best, at, bic, whiteness_z(best.residuals), search,
                               cal.scan_at)
