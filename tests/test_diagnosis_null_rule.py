"""A candidate's reported fit is never worse than the null model it contains (issue 20, item 13):
when the null is refitted to a better basin after the candidates were fitted, a candidate that
ended above the new null is reported *at* it — the null's fit, residual and nominal values, its
effect at "no effect", no significance of its own — and the report and the figures name it
with one word."""

from __future__ import annotations

import math
from types import SimpleNamespace

import numpy as np
import pytest

from idm_rs.core.batch import Structure
from idm_rs.diagnosis.candidates import against_null, make_candidate
from idm_rs.diagnosis.case_model import ModelSpec
from idm_rs.diagnosis.catalogue import CATALOGUE
from idm_rs.diagnosis.fitting import FitResult
from idm_rs.diagnosis.problem import CalibratedNull, Refit
from idm_rs.diagnosis.thresholds import CALIBRATED


def _fit(chi2: float, n: int, values: dict[str, float], spec: ModelSpec) -> FitResult:
    rng = np.random.default_rng(int(chi2))
    res = rng.normal(0.0, 1.0, n)
    res *= math.sqrt(chi2 / float(np.sum(res ** 2)))  # sigma = 1: chi2 is the residual energy
    return FitResult(dict(values), {k: 0.01 for k in values}, chi2, n, [res], [0.0], spec, 10, True, "")


def test_a_candidate_above_a_refitted_null_is_reported_at_that_null():
    n = 1000
    pb = SimpleNamespace(ln_n=math.log(n), n_offsets=1, sigma=1.0, obj=None)
    spec = ModelSpec(Structure("lps", 1), {"mu_k": 0.5, "m2": 0.3}, {})
    eff = next(e for e in CATALOGUE if e.id == "incline")
    free = [SimpleNamespace(name=k) for k in CALIBRATED]
    nominal = {k: 1.0 for k in CALIBRATED}

    def calibration(chi2: float, mu_k: float) -> CalibratedNull:
        f = _fit(chi2, n, {**nominal, "mu_k": mu_k}, spec)
        bic = chi2 + (len(free) + pb.n_offsets) * pb.ln_n
        return CalibratedNull(free, f, [], f, [], bic, 0.0, None)  # type: ignore[arg-type]

    first, better = calibration(2600.0, 0.50), calibration(1650.0, 0.46)
    # fitted against the first null: better than it, worse than the refitted one
    values = {**nominal, "mu_k": 0.49, **{ep.name: 3e-4 for ep in eff.params}}
    r = _fit(2400.0, n, values, spec)
    r.std.update({ep.name: 1e-5 for ep in eff.params})  # "30 σ from no effect" on its own
    c = make_candidate(pb, first, eff, r, screened_only=False)
    assert c.significance[eff.params[0].name] > 10 and c.fit_label == "fitted"
    at = SimpleNamespace(at=lambda v: ("at", v))
    refit = Refit(c, spec, [SimpleNamespace(name="mu_k", at=at.at), SimpleNamespace(name=eff.params[0].name,
                                                                                    at=at.at)])
    against_null(pb, better, refit)
    c = refit.candidate
    assert c.at_null and c.fit_label == "at null"
    assert c.chi2 == better.fit.chi2 and c.rms_after == pytest.approx(better.fit.rms)
    assert c.calibrated["mu_k"] == 0.46  # the null's nominal values
    assert all(v == 0.0 for v in c.significance.values())  # its effect at "no effect"
    assert all(v == ep.none for ep, v in zip(eff.params, (c.params[ep.name] for ep in eff.params)))
    assert c.lr_chi2 == 0.0
    # the BIC of the null plus the effect's parameters: a few ln n below, not thousands
    assert c.delta_bic == pytest.approx(-len(eff.params) * pb.ln_n)
    # a candidate better than the new null keeps its fit, its ΔBIC taken against the new null
    good = make_candidate(pb, first, eff, _fit(1500.0, n, values, spec), screened_only=False)
    keep = Refit(good, spec, [])
    against_null(pb, better, keep)
    assert keep.candidate is good and not good.at_null and good.chi2 == 1500.0
    assert good.delta_bic == pytest.approx(better.bic - good.bic) and good.lr_chi2 == pytest.approx(150.0)
    # a score-only candidate's linearised numbers, taken at the first null, are capped at the new one
    lin = make_candidate(pb, first, eff, _fit(2000.0, n, values, spec), screened_only=True)
    capped = Refit(lin, spec, [])
    against_null(pb, better, capped)
    assert lin.chi2 == better.fit.chi2 and lin.fit_label == "score only"
