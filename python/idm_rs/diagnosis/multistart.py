"""Multistart least squares, as the field fits ODE models (Raue et al. 2013, PLoS ONE 8:e74335;
Villaverde et al. 2019; pyPESTO/AMICI): many starts, ranked by their misfit in one batch call;
local fits on exact Jacobians (:func:`.fitting.fit`) from the best distinct ones; every local
fit reports where it started and where it ended. The best end, and how many local fits reached
it, are the convergence evidence."""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Callable, Optional, Sequence

import numpy as np

from .case_model import ModelSpec
from .fitting import FitResult, FreeParam, Objective, apply, fit_progressive
from .thresholds import AGREE_CHI2, NOISE_CHI2_Z, NOISE_WHITENESS_Z, PROMISING
from .whiteness import whiteness_z


@dataclass(frozen=True)
class Start:
    """One start: a label saying where it comes from, and the free parameters centred on it."""

    label: str
    free: list[FreeParam]
    #: starts of one origin (e.g. "nominal values"); see `multistart`'s `always`
    group: str = ""


@dataclass
class LocalFit:
    """Where one local fit started and ended."""

    label: str
    start: dict[str, float]
    start_chi2: float  #: over the ranking horizon
    fit: FitResult

    def to_dict(self) -> dict[str, Any]:
        return {"start": self.label, "start_values": self.start, "start_chi2_ranking_horizon": self.start_chi2,
                "end_chi2": self.fit.chi2, "end_values": self.fit.values, "evaluations": self.fit.nfev}


@dataclass
class MultiStart:
    """Every local fit (best first) and how many starts were ranked."""

    fits: list[LocalFit]
    ranked: int  #: starts simulated and ranked before the local fits
    ranking_cycles: Optional[int]
    #: local fits planned but not run: an earlier one left noise (`multistart(stop_at_noise)`)
    skipped: int = 0

    @property
    def best(self) -> FitResult:
        return self.fits[0].fit

    def agree(self, chi2: float) -> bool:
        return agree(self.best, chi2)

    @property
    def reached(self) -> int:
        """Local fits that ended at the best optimum (see `agree`)."""
        return sum(self.agree(f.fit.chi2) for f in self.fits)

    def summary(self) -> str:
        chis = ", ".join(f"{f.fit.chi2:.0f} (from {f.label})" for f in self.fits)
        over = "the whole record" if self.ranking_cycles is None else f"the first {self.ranking_cycles} cycle(s)"
        return (f"{self.ranked} starts ranked over {over}; "
                f"{len(self.fits)} local fits on exact Jacobians ended at chi^2 {chis}; "
                f"{self.reached} of {len(self.fits)} reached the best"
                + (f"; {self.skipped} more not run: a fit left noise" if self.skipped else ""))

    def to_dict(self) -> dict[str, Any]:
        return {"ranked": self.ranked, "reached": self.reached, "skipped": self.skipped,
                "local_fits": [f.to_dict() for f in self.fits]}


def agree(best: FitResult, chi2: float) -> bool:
    """A fit ending at `chi2` reached `best`'s optimum: within AGREE_CHI2 residual variances."""
    return chi2 - best.chi2 <= AGREE_CHI2 * max(1.0, best.chi2 / max(best.n, 1))


def fit_at_noise(fit: FitResult) -> bool:
    """The fit's residual is indistinguishable from the noise by its chi^2 (within NOISE_CHI2_Z
    of n) and white (NOISE_WHITENESS_Z): a multistart's stopping rule, stricter than the
    verdict's :func:`.rules.leaves_noise` (RMS within 1.1 sigma)."""
    n = max(fit.n, 1)
    return (fit.chi2 <= n + NOISE_CHI2_Z * math.sqrt(2.0 * n)
            and abs(whiteness_z(fit.residuals)) <= NOISE_WHITENESS_Z)


def _key(free: Sequence[FreeParam]) -> np.ndarray:
    """A start's position in fit units (log-scaled parameters in log units), for distinctness."""
    return np.array([math.log(max(f.x0, 1e-300)) / f.scale if f.log else f.x0 / f.scale for f in free])


def distinct(order: Sequence[int], starts: Sequence[Start], k: int, min_distance: float = 0.5) -> list[int]:
    """Up to `k` of `order` (best first), each at least `min_distance` fit units away from every
    one already taken in some parameter: local fits from next-door starts tell nothing new."""
    taken: list[int] = []
    for i in order:
        if len(taken) >= k:
            break
        ki = _key(starts[i].free)
        if all(np.max(np.abs(ki - _key(starts[j].free))) >= min_distance for j in taken):
            taken.append(i)
    return taken


def rank(objective: Objective, base: ModelSpec, starts: Sequence[Start], cycles: Optional[int],
         progress: Optional[Callable[..., Any]] = None) -> list[float]:
    """chi^2 of every start over the first `cycles` cycles: one batch call for all of them."""
    obj = objective.with_cycles(cycles)
    specs = [apply(base, s.free, np.zeros(len(s.free))) for s in starts]
    # with the fits' retries at a finer step: a start a local fit ended at (the null fit) may
    # need them, and a start ranked as failed never gets its local fit
    preds = obj.predict(specs)
    if progress:
        progress(len(specs))
    return [float(np.sum(obj.vector(p) ** 2)) for p in preds]


def multistart(objective: Objective, base: ModelSpec, starts: Sequence[Start], *, local_fits: int,
               horizons: Sequence[Optional[int]] = (2, None), max_nfev: Sequence[int] = (10, 10),
               always: Sequence[str] = (), stop_at_noise: bool = False,
               progress: Optional[Callable[..., Any]] = None) -> MultiStart:
    """Rank `starts` over the first horizon, then fit from the `local_fits` best distinct ones
    among the promising (within PROMISING of the best start's chi^2), and from the best-ranked
    start of every group in `always` (a start's misfit is not its basin: the nominal values
    as given, with a large effect in place, can start far up a slope that leads to the truth),
    over each horizon in turn, in that order; with `stop_at_noise`, no more once one fit
    leaves noise (`fit_at_noise`). The fits best first."""
    chis = rank(objective, base, starts, horizons[0], progress)
    order = sorted(range(len(starts)), key=lambda i: chis[i] if math.isfinite(chis[i]) else math.inf)
    promising = [i for i in order if chis[i] <= PROMISING * chis[order[0]]]
    picks = distinct(promising, starts, local_fits)
    for g in always:
        i = next((i for i in order if starts[i].group == g), None)
        if i is not None and i not in picks and all(starts[j].group != g for j in picks):
            picks.append(i)
    fits: list[LocalFit] = []
    for i in picks:
        s = starts[i]
        r = fit_progressive(objective, base, s.free, horizons=horizons, max_nfev=max_nfev, progress=progress)
        fits.append(LocalFit(s.label, {f.name: f.x0 for f in s.free}, chis[i], r))
        if stop_at_noise and fit_at_noise(r):
            break
    fits.sort(key=lambda f: f.fit.chi2)
    return MultiStart(fits, len(starts), horizons[0], len(picks) - len(fits))
