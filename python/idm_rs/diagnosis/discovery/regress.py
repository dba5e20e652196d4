"""Step 2, the force's form found: sparse regression (orthogonal matching pursuit) of the inferred
force's effect on the readings on the library terms' effects, the number of terms and the
periodic wavelength chosen by cross-validation across experiments (:func:`find_terms`)."""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from typing import Sequence

import numpy as np
from numpy.typing import NDArray

from ..thresholds import (
    ALIAS_SHARE,
    DEGENERATE_COS,
    FORM_CV_MAX,
    MAX_TERMS,
    PERIODIC_GAIN,
    TERM_GAIN,
    TERM_SHARE,
    WAVELENGTHS,
)
from .infer import InferredForce, knot_view
from .library import MAIN_TERMS, QUADRATURE, WEIGHT_TERMS, Term
from .linalg import lstsq, require_finite


@dataclass
class FoundForm:
    """The library terms that reproduce the inferred force, chosen by cross-validation."""

    body: str
    terms: list[Term]
    coefficients: dict[str, float]  #: engine parameter -> value (regression estimate)
    wavelength: float  #: [m], 0 when no periodic term
    cv_error: float  #: leave-one-experiment-out error, relative to the force's own
    cv_by_size: list[float]  #: the same for 0, 1, 2, ... terms
    candidates: list[tuple[str, float]] = field(default_factory=list)  #: (form, cv error) tried
    notes: list[str] = field(default_factory=list)  #: what limits the form (e.g. dependent terms)
    #: where it was found: "inferred force" (its effect on the readings), "inferred force,
    #: calibration projected out", or "residual (direct)"
    source: str = "inferred force"
    #: (a chosen term, a library term left out, |cos| of their effects on the readings) for each
    #: pair at or above DEGENERATE_COS: look-alikes these experiments cannot tell apart, so the
    #: term chosen names one of two physics (a force c V and the PE's extension x2 - x1, which
    #: follows d33 V)
    look_alikes: list[tuple[str, str, float]] = field(default_factory=list)
    #: for each look-alike pair (chosen symbol, other symbol): the other term and its coefficient
    #: when it replaces the chosen one in the regression (the start of that form's refit)
    swaps: dict[tuple[str, str], tuple[Term, float]] = field(default_factory=dict)

    def swapped(self, chosen: str, other: str) -> "FoundForm":
        """This form with term `chosen` replaced by its look-alike `other` (:attr:`swaps`),
        the other coefficients as they are."""
        term, value = self.swaps[(chosen, other)]
        terms = [term if t.symbol == chosen else t for t in self.terms]
        coefficients = {t.param: (value if t is term else self.coefficients[t.param]) for t in terms}
        return replace(self, terms=terms, coefficients=coefficients, look_alikes=[], swaps={})

    @property
    def variables(self) -> list[str]:
        return sorted({t.variable for t in self.terms})


def _design(force: InferredForce, terms: Sequence[Term], wavelength: float, project: bool = False
            ) -> tuple[list[NDArray[np.float64]], list[NDArray[np.float64]]]:
    """Per experiment: the library terms' effect on the readings (samples x terms; the exact
    derivatives at the inferred force's run, `InferredForce.library_view`, or through the knots
    for a force made without the engine) and the inferred force's own effect (samples): both in
    noise units; with `project`, in the complement of the calibrated parameters' directions."""
    y = force.target if force.target is not None else [A @ v for A, v in zip(force.jacobians, force.values)]
    if force.with_nuisance and force.nuisance and force.nuisance_u is not None:
        # the total correction: what the calibrated parameters took while the force was
        # inferred goes back in (a drag c v1 on the main body, inferred from mis-set nominal
        # values: mu_k rose 13 % and took the drag's sign-like part, and the force alone looked
        # like v1|v1| (|cos| 0.97 against 0.89 for v1); force and moves together are v1 at
        # -122.5 N s/m for the true -122.4, 0.9 % unexplained)
        y = [yj + S @ force.nuisance_u for yj, S in zip(y, force.nuisance)]
    if force.library_view is not None:
        X = force.library_view(terms, wavelength)
    else:
        X = [knot_view(force, j, terms, wavelength) for j in range(len(force.jacobians))]
    if force.nuisance and project:
        # what the refit's calibrated parameters can absorb is no evidence for a term (the
        # calibration already moved them to mimic the missing physics): the library's and the
        # force's effects are compared in the complement of those directions (Frisch-Waugh)
        S = np.concatenate(force.nuisance)
        Q, _ = np.linalg.qr(S[:, np.linalg.norm(S, axis=0) > 0])
        sizes = np.cumsum([x.shape[0] for x in X])[:-1]
        Xa, ya = np.concatenate(X), np.concatenate(y)
        before = np.linalg.norm(Xa, axis=0)
        Xa = Xa - Q @ (Q.T @ Xa)
        ya = ya - Q @ (Q.T @ ya)
        # a term whose effect the parameters make almost entirely (Ff: a friction level, mu_k)
        # is their alias, not a form: left out rather than scaled up from what remains
        alias = np.linalg.norm(Xa, axis=0) < ALIAS_SHARE * np.maximum(before, 1e-300)
        Xa[:, alias] = 0.0
        X, y = np.split(Xa, sizes), np.split(ya, sizes)
    return X, y


def _cv_path(X: list[NDArray[np.float64]], y: list[NDArray[np.float64]], max_terms: int, noisy: bool = False
             ) -> tuple[list[float], list[NDArray[np.int64]]]:
    """The supports of orthogonal matching pursuit on all experiments with 1..max_terms terms,
    and each support's leave-one-experiment-out error (least squares on the others, predicting
    the one left out), relative to the force's own effect; 0 terms has error 1. The supports are
    chosen once, on all data: a pursuit run per fold picks among nearly collinear terms (v1,
    v1|v1|, dV/dt on one-way slips) by the fold's accidents, and its error then measures those
    accidents, not the form. With `noisy` (a target that is the residual itself, white noise of
    unit variance per sample in it), the noise a perfect form leaves is taken off both the
    held-out error and the target's energy: the error is then the share of the systematic part
    left unexplained."""
    Xa = np.concatenate(X)
    require_finite("the library's effect on the readings", library=Xa, force=np.concatenate(y))
    norms = np.sqrt(np.sum(Xa * Xa, axis=0))
    norms[norms == 0] = 1.0
    ya = np.concatenate(y)
    total = float(ya @ ya) - (ya.size if noisy else 0.0)
    errs: list[float] = [1.0]
    supports: list[NDArray[np.int64]] = [np.zeros(0, dtype=np.int64)]
    if total <= 0.0:
        return errs, supports
    m = len(X)
    path = _omp_path(Xa / norms, ya, max_terms)
    for k in range(1, max_terms + 1):
        support = path[min(k, len(path)) - 1] if path else np.zeros(0, dtype=np.int64)
        if support.size < k and k > 1:
            break  # the library has no more independent directions
        sse = 0.0
        for hold in range(m):
            rest = [i for i in range(m) if i != hold]
            c = lstsq(np.concatenate([X[i][:, support] for i in rest]), np.concatenate([y[i] for i in rest]),
                       "the form's cross-validation")[0]
            r = y[hold] - X[hold][:, support] @ c
            sse += float(r @ r) - (r.size if noisy else 0.0)
        errs.append(sse / total)
        supports.append(support)
    return errs, supports


def _omp_path(X: NDArray[np.float64], y: NDArray[np.float64], max_terms: int) -> list[NDArray[np.int64]]:
    """The supports of orthogonal matching pursuit (scikit-learn) after 1, 2, ... terms, up to
    `max_terms`: one greedy pursuit whose k-th step is the pursuit stopped at k terms, on the
    Gram matrix formed once (the library has many samples and few columns). A library whose
    columns are linearly dependent (V and x1 - x2 follow each other) stops early: fewer steps."""
    import warnings

    from sklearn.linear_model import orthogonal_mp_gram

    n = X.shape[1]
    # formed as scikit-learn's estimator forms them, so the pursuit is the estimator's
    gram = np.empty((n, n), dtype=X.dtype, order="C")
    np.dot(X.T, X, out=gram)
    xy = np.empty(n, dtype=X.dtype, order="C")
    np.dot(X.T, y, out=xy)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        coef = orthogonal_mp_gram(gram, xy, n_nonzero_coefs=min(max_terms, n), return_path=True)
    coef = np.reshape(coef, (n, -1))
    return [np.flatnonzero(coef[:, k]) for k in range(coef.shape[1])]


def _choose(errs: list[float]) -> int:
    """The number of terms: each one more must lower the cross-validated error by TERM_GAIN
    of it and by TERM_SHARE of the force's own effect (the inferred force is itself an
    estimate, knot-limited and smoothed: a term that explains a percent of it explains its
    artefacts); 0 unless the form explains more than FORM_CV_MAX of the force out of sample.
    The greedy pursuit may need a second term before the first pays off, so a size is judged
    against every smaller one, not only the one before."""
    k = 0
    for i in range(1, len(errs)):
        if errs[i] <= min(TERM_GAIN * errs[k], errs[k] - TERM_SHARE):
            k = i
    return k if errs[k] < FORM_CV_MAX else 0


def find_terms(force: InferredForce, max_terms: int = MAX_TERMS, project: bool = False) -> FoundForm:
    """The library terms (module docstring, step 2) that best reproduce `force`: orthogonal
    matching pursuit, the number of terms and the wavelength of the periodic ones chosen by
    leave-one-experiment-out cross-validation. With `project`, the regression is done in the
    complement of what the calibrated parameters can move (their aliases left out)."""
    library = MAIN_TERMS if force.body == "main" else WEIGHT_TERMS
    plain = [t for t in library if not t.periodic]
    periodic = [t for t in library if t.periodic]
    tried: list[tuple[str, float]] = []

    def evaluate(terms: list[Term], wavelength: float) -> tuple[list[float], int, list[NDArray[np.float64]],
                                                                list[NDArray[np.float64]], list[NDArray[np.int64]]]:
        X, y = _design(force, terms, wavelength, project)
        errs, supports = _cv_path(X, y, max_terms, noisy=force.target is not None)
        k = _choose(errs)
        return errs, k, X, y, supports

    best = evaluate(plain, 0.0)
    best_terms, best_wl = plain, 0.0
    tried.append(("without periodic terms", best[0][best[1]]))
    if periodic:
        for wl in WAVELENGTHS:
            cand = evaluate(plain + periodic, float(wl))
            err, err_best = cand[0][cand[1]], best[0][best[1]]
            tried.append((f"periodic, lambda = {wl * 1e6:.3g} um", err))
            # the wavelength is a choice the data must pay for: against the plain form, by the
            # same margins as a term; against another wavelength, by being lower
            margin = min(PERIODIC_GAIN * err_best, err_best - TERM_SHARE) if best_wl == 0.0 else err_best
            if err < margin:
                best, best_terms, best_wl = cand, plain + periodic, float(wl)
    errs, k, X, y, supports = best
    notes: list[str] = []
    chosen: list[Term] = []
    coefs: dict[str, float] = {}
    if k > 0:
        support = supports[k]
        coef, rank = lstsq(np.concatenate(X)[:, support], np.concatenate(y), "the form's coefficients")
        if rank < support.size:
            notes.append(f"the {support.size} terms chosen are linearly dependent on these experiments (rank "
                         f"{rank}): their coefficients are not determined one by one")
        for i, c in zip(support, coef):
            chosen.append(best_terms[i])
            coefs[best_terms[i].param] = float(c)
    wl = best_wl if any(t.periodic for t in chosen) else 0.0
    source = ("residual (direct)" if force.target is not None
              else "inferred force, calibration projected out" if project
              else "inferred force with the calibrated parameters' moves" if force.with_nuisance
              else "inferred force")
    support = supports[k] if k > 0 else np.zeros(0, dtype=np.int64)
    Xa, ya = np.concatenate(X), np.concatenate(y)
    alike = _look_alikes(Xa, best_terms, support)
    swaps = {}
    index = {t.symbol: i for i, t in enumerate(best_terms)}
    for a, b, _ in alike:
        other = np.array([index[b] if i == index[a] else i for i in support])
        c = lstsq(Xa[:, other], ya, "a look-alike's coefficients")[0]
        swaps[(a, b)] = (best_terms[index[b]], float(c[list(other).index(index[b])]))
    return FoundForm(force.body, chosen, coefs, wl, float(errs[k]), [float(e) for e in errs], tried, notes, source,
                     alike, swaps)


def _look_alikes(X: NDArray[np.float64], terms: Sequence[Term], support: NDArray[np.int64]
                 ) -> list[tuple[str, str, float]]:
    """(chosen symbol, other symbol, |cos|) for every chosen term (columns `support` of `X`, the
    library terms' effects on the readings) and every term left out whose effect is parallel to
    it within DEGENERATE_COS: to first order the data cannot tell the two apart."""
    norms = np.linalg.norm(X, axis=0)
    out = []
    for i in support:
        for j in range(len(terms)):
            if j in support or norms[i] == 0.0 or norms[j] == 0.0:
                continue
            cos = abs(float(X[:, i] @ X[:, j])) / (norms[i] * norms[j])
            if cos >= DEGENERATE_COS:
                out.append((terms[int(i)].symbol, terms[j].symbol, cos))
    return sorted(out, key=lambda a: -a[2])


def with_quadrature(form: FoundForm) -> FoundForm:
    """The form with each periodic term's quadrature partner added (at zero) where it lacks
    it: a force periodic in position has a phase, which one term at a fixed phase cannot carry.
    The regression may pick one of the pair, the other below its cross-validation threshold;
    a phase 0.1 rad off a 2 % periodic friction leaves ~10 % of its effect unexplained. The
    refit prunes a partner it does not support."""
    have = {t.param for t in form.terms}
    by_param = {t.param: t for t in MAIN_TERMS}
    extra = [by_param[QUADRATURE[t.param]] for t in form.terms if t.periodic and QUADRATURE[t.param] not in have]
    if not extra:
        return form
    coefficients = dict(form.coefficients)
    for t in extra:
        coefficients[t.param] = 0.0
    return replace(form, terms=list(form.terms) + extra, coefficients=coefficients)
