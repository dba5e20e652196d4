"""Global calibration of the nominal subset, multistart as the field does it: a population
search over the plausible ranges (differential evolution, the whole population simulated in one
batch call per generation) on the segmented misfit over the first drive cycle, and
Latin-hypercube starts over the same ranges, and starts from each parameter's 1-D scan; all of
them ranked in one batch call, and local
least-squares fits on exact Jacobians from the best distinct ones over two cycles, then
everything (:mod:`.multistart`). How many local fits reached the best optimum is the
convergence evidence the verdict and the report use."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Callable, Optional, Sequence, cast

import numpy as np
from numpy.typing import NDArray

from .case_model import ModelSpec
from .fitting import FitResult, FreeParam, Objective, apply
from .multistart import MultiStart, Start, multistart
from .thresholds import (
    CALIBRATION_HORIZONS,
    CALIBRATION_LOCAL_FITS,
    CALIBRATION_NFEV,
    LHS_STARTS,
    SCAN_CYCLES,
    SCAN_POINTS,
    SEARCH_CYCLES,
    SEARCH_GENERATIONS,
    SEARCH_POLISHES,
    SEARCH_POPULATION_PER_PARAM,
)


@dataclass
class Calibration:
    """The calibrated nominal subset and the evidence that the search converged."""

    fit: FitResult  #: the best local fit over everything
    polishes: list[FitResult]  #: every local fit, best first
    search_best: float  #: the population search's best chi^2 over its horizon
    evaluations: int  #: models simulated by the search
    converged: bool  #: more than one local fit reached the best optimum (or it is at the noise floor)
    #: the search's best member (u of each free parameter): the optimum over the first cycle(s),
    #: before the fit over everything (where a missing effect may pull the nominal values)
    search_u: Optional[NDArray[np.float64]] = None
    multistart: Optional[MultiStart] = None
    #: the best 1-D scan start (u; None when no scan beat the nominal values): the nominal
    #: values with one side basin left, where the candidates also start (see `scan_starts`)
    scan_u: Optional[NDArray[np.float64]] = None
    #: the drive cycles the search ran over (None: the whole record)
    search_cycles: Optional[int] = SEARCH_CYCLES

    def summary(self) -> str:
        verdict = "converged" if self.converged else "NOT CONVERGED"
        ms = self.multistart.summary() if self.multistart is not None else ""
        over = "the whole record" if self.search_cycles is None else f"the first {self.search_cycles} cycle(s)"
        return f"population search ({self.evaluations} models over {over}); {ms} ({verdict})"


def search(objective: Objective, base: ModelSpec, free: Sequence[FreeParam], *, seed: int = 0,
           cycles: Optional[int] = SEARCH_CYCLES, population_per_param: Optional[int] = None,
           generations: Optional[int] = None, progress: Optional[Callable[..., Any]] = None
           ) -> tuple[list[NDArray[np.float64]], float, int]:
    """Differential evolution over the free parameters' bounds (u space) on `objective` over
    its first `cycles` cycles (None: the whole record), the free parameters' starting point (u = 0) one member of the
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
    popsize = population_per_param or SEARCH_POPULATION_PER_PARAM
    rng = np.random.default_rng(seed)
    lo = np.array([b[0] for b in bounds])
    hi = np.array([b[1] for b in bounds])
    init = lo + (hi - lo) * _spread_points(popsize * n, n, rng)
    init[0] = np.clip(np.zeros(n), lo, hi)
    res = differential_evolution(chi2_of, bounds, vectorized=True, updating="deferred",
                                 init=init, maxiter=generations or SEARCH_GENERATIONS, tol=1e-3, mutation=(0.5, 1.0),
                                 recombination=0.7, seed=seed, polish=False)
    pop, energies = np.asarray(res.population), np.asarray(res.population_energies)
    order = np.argsort(energies)
    picks = [pop[order[0]]]
    span = hi - lo
    for i in order[1:]:
        if len(picks) >= SEARCH_POLISHES:
            break
        # distinct: at least 5 % of the range away from every pick in some parameter
        if all(np.max(np.abs(pop[i] - p) / span) > 0.05 for p in picks):
            picks.append(pop[i])
    return picks, float(energies[order[0]]), count[0]


def _spread_points(m: int, d: int, rng: np.random.Generator) -> NDArray[np.float64]:
    from scipy.stats import qmc

    return cast("NDArray[np.float64]", qmc.LatinHypercube(d, seed=rng).random(m))


def scan_starts(objective: Objective, base: ModelSpec, free: Sequence[FreeParam], *,
                points: int = SCAN_POINTS, cycles: int = SCAN_CYCLES,
                progress: Optional[Callable[..., Any]] = None) -> list[tuple[str, NDArray[np.float64]]]:
    """Starts from 1-D scans: each free parameter over a grid of its range with the others at
    their starting values (u = 0), all simulated in one batch call. A parameter whose misfit
    oscillates along its range — a mass that sets a resonance the drive excites, off by 10 %,
    puts the response out of phase — has side basins that a local fit from its nominal value
    falls into, and that a population search over all parameters at once resolves poorly (the
    true basin is a few percent wide in that one direction). Returns the nominal values with
    the parameter that gains most at its scan's best, and with every parameter that gains at
    its best (labels name them); none if no scan beats the nominal values."""
    obj = objective.with_cycles(cycles)
    n = len(free)
    grids = [np.linspace(*f.u_bounds(), points) for f in free]
    us = [np.zeros(n)] + [np.where(np.arange(n) == k, x, 0.0) for k, g in enumerate(grids) for x in g]
    preds = obj.predict([apply(base, free, u) for u in us], retries=0)
    if progress:
        progress(len(us))
    chi = np.array([float(np.sum(obj.vector(p) ** 2)) for p in preds])
    chi = np.where(np.isfinite(chi), chi, np.inf)
    at_nominal, per = chi[0], chi[1:].reshape(n, points)
    best_k = per.argmin(axis=1)
    gain = at_nominal - per[np.arange(n), best_k]
    better = [k for k in range(n) if gain[k] > 0]
    if not better:
        return []
    top = max(better, key=lambda k: gain[k])
    one = np.zeros(n)
    one[top] = grids[top][best_k[top]]
    out = [(f"1-D scan best ({free[top].name})", one)]
    if len(better) > 1:
        every = np.zeros(n)
        for k in better:
            every[k] = grids[k][best_k[k]]
        out.append(("1-D scans combined (" + ", ".join(free[k].name for k in better) + ")", every))
    return out


#: the start groups a calibration always fits from locally (besides the best-ranked distinct start)
ALWAYS_FITTED: tuple[str, ...] = ("population search best", "nominal values", "1-D scan")


def calibrate(objective: Objective, base: ModelSpec, free: Sequence[FreeParam], *, seed: int = 0,
              always: Sequence[str] = ALWAYS_FITTED, cycles: Optional[int] = SEARCH_CYCLES,
              horizons: Sequence[Optional[int]] = CALIBRATION_HORIZONS, max_nfev: Sequence[int] = CALIBRATION_NFEV,
              progress: Optional[Callable[..., Any]] = None) -> Calibration:
    """Search, then multistart: the search's distinct good members, the nominal point and
    Latin-hypercube points over the ranges, ranked together; local fits from the best distinct
    and from the best start of each group in `always` (a caller that has fitted from the nominal
    point already leaves "nominal values" out). The search runs over the first `cycles` drive
    cycles (None: the whole record), the ranking over the first of `horizons` and each local fit
    over `horizons` in turn with `max_nfev` evaluations each."""
    picks, best, evaluations = search(objective, base, free, seed=seed, cycles=cycles, progress=progress)
    bounds = np.array([f.u_bounds() for f in free])
    lhs = bounds[:, 0] + (bounds[:, 1] - bounds[:, 0]) * _spread_points(LHS_STARTS, len(free),
                                                                        np.random.default_rng(seed + 1))
    points = [("population search best" if i == 0 else f"population search member {i + 1}", u)
              for i, u in enumerate(picks)]
    points.append(("nominal values", np.clip(np.zeros(len(free)), bounds[:, 0], bounds[:, 1])))
    points += [(f"Latin hypercube {i + 1}", u) for i, u in enumerate(lhs)]
    starts = [Start(label, [f.at(f.value(float(x))) for f, x in zip(free, u)], label) for label, u in points]
    scans = scan_starts(objective, base, free, progress=progress)
    starts += [Start(label, [f.at(f.value(float(x))) for f, x in zip(free, u)], "1-D scan") for label, u in scans]
    # the search's best member, the nominal values as given and the best 1-D scan start always
    # get a local fit: the search optimised the first cycle, which two cycles may rank
    # differently; on a healthy device the nominal values are 5-15 % from the truth, in its
    # basin, however they compare; a scan finds a side basin's way out (see `scan_starts`)
    ms = multistart(objective, base, starts, local_fits=CALIBRATION_LOCAL_FITS, horizons=horizons, max_nfev=max_nfev,
                    always=always, progress=progress)
    top = ms.best
    # converged: the best optimum was reached from more than one start (or the best local fit
    # ends at the noise floor)
    noise_floor = top.chi2 <= 1.1**2 * top.n
    converged = ms.reached >= 2 or noise_floor
    return Calibration(top, [f.fit for f in ms.fits], best, evaluations, converged, picks[0], ms,
                       scans[0][1] if scans else None, cycles)
