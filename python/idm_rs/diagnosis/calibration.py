"""Global calibration of the nominal subset: a population search over the plausible ranges
(differential evolution, the whole population simulated in one batch call per generation) on
the segmented misfit over the first drive cycles, then least squares over everything from the
best member and from distinct runners-up. Whether the independent polishes agree is the
convergence evidence the verdict and the report use."""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Callable, Optional, Sequence

import numpy as np
from numpy.typing import NDArray

from .case_model import ModelSpec
from .fitting import FitResult, FreeParam, Objective, apply, fit_progressive

#: drive cycles of every experiment the population search compares (cheap and smooth)
SEARCH_CYCLES = 1
#: population per free parameter and generations of the search
POPULATION_PER_PARAM = 6
GENERATIONS = 25
#: independent polishes (the best member and the most distinct good runners-up)
POLISHES = 2
#: two polishes agree when their chi^2 differ by less than this (noise units) ...
AGREE_CHI2 = 25.0


@dataclass
class Calibration:
    """The calibrated nominal subset and the evidence that the search converged."""

    fit: FitResult  #: the best polish over everything
    polishes: list[FitResult]  #: every polish, best first
    search_best: float  #: the population search's best chi^2 over its horizon
    evaluations: int  #: models simulated by the search
    converged: bool  #: the independent polishes reached the same optimum
    #: the search's best member (u of each free parameter): the optimum over the first cycle(s),
    #: before the polish over everything (where a missing effect may pull the nominal values)
    search_u: Optional[NDArray[np.float64]] = None

    def summary(self) -> str:
        chis = ", ".join(f"{p.chi2:.0f}" for p in self.polishes)
        verdict = "agree" if self.converged else "DISAGREE"
        return (f"population search ({self.evaluations} models over the first {SEARCH_CYCLES} cycle(s)), "
                f"{len(self.polishes)} independent polishes over everything: chi^2 {chis} ({verdict})")


def search(objective: Objective, base: ModelSpec, free: Sequence[FreeParam], *, seed: int = 0,
           cycles: int = SEARCH_CYCLES, population_per_param: Optional[int] = None,
           generations: Optional[int] = None, progress: Optional[Callable[..., Any]] = None
           ) -> tuple[list[NDArray[np.float64]], float, int]:
    """Differential evolution over the free parameters' bounds (u space) on `objective` over
    its first `cycles` cycles, the free parameters' starting point (u = 0) one member of the
    first population; returns distinct good members (u, best first), the best chi^2 and the
    number of models simulated."""
    from scipy.optimize import differential_evolution

    obj = objective.with_cycles(cycles)
    bounds = [f.u_bounds() for f in free]
    count = [0]

    def chi2_of(U: NDArray[np.float64]) -> NDArray[np.float64]:
        # vectorized: U is (parameters, members), one batch call for the whole generation
        specs = [apply(base, free, U[:, s]) for s in range(U.shape[1])]
        preds = obj.predict(specs, retries=0)
        count[0] += len(specs)
        if progress:
            progress(len(specs))
        return np.array([float(np.sum(obj.vector(p) ** 2)) for p in preds])

    # the nominal point itself is one member of the first population
    n = len(free)
    popsize = population_per_param or POPULATION_PER_PARAM
    rng = np.random.default_rng(seed)
    lo = np.array([b[0] for b in bounds])
    hi = np.array([b[1] for b in bounds])
    init = lo + (hi - lo) * _spread_points(popsize * n, n, rng)
    init[0] = np.clip(np.zeros(n), lo, hi)
    res = differential_evolution(chi2_of, bounds, vectorized=True, updating="deferred",
                                 init=init, maxiter=generations or GENERATIONS, tol=1e-3, mutation=(0.5, 1.0),
                                 recombination=0.7, seed=seed, polish=False)
    pop, energies = np.asarray(res.population), np.asarray(res.population_energies)
    order = np.argsort(energies)
    picks = [pop[order[0]]]
    span = hi - lo
    for i in order[1:]:
        if len(picks) >= POLISHES:
            break
        # distinct: at least 5 % of the range away from every pick in some parameter
        if all(np.max(np.abs(pop[i] - p) / span) > 0.05 for p in picks):
            picks.append(pop[i])
    return picks, float(energies[order[0]]), count[0]


def _spread_points(m: int, d: int, rng: np.random.Generator) -> NDArray[np.float64]:
    from scipy.stats import qmc

    return qmc.LatinHypercube(d, seed=rng).random(m)


def calibrate(objective: Objective, base: ModelSpec, free: Sequence[FreeParam], *,
              progress: Optional[Callable[..., Any]] = None) -> Calibration:
    """Search, then polish each distinct good member over two cycles and everything."""
    picks, best, evaluations = search(objective, base, free, progress=progress)
    polishes = []
    for u in picks:
        start = [f.at(f.value(float(x))) for f, x in zip(free, u)]
        polishes.append(fit_progressive(objective, base, start, horizons=(2, None), max_nfev=(12, 15),
                                        progress=progress))
    polishes.sort(key=lambda r: r.chi2)
    top = polishes[0]
    agreeing = [p for p in polishes if p.chi2 - top.chi2 <= max(AGREE_CHI2, 1e-3 * top.chi2)]
    # converged: the best optimum was reached from more than one start (or the single start
    # there is ends at the noise floor)
    noise_floor = top.chi2 <= 1.1**2 * top.n
    converged = len(agreeing) >= 2 or noise_floor
    return Calibration(top, polishes, best, evaluations, converged, picks[0])
