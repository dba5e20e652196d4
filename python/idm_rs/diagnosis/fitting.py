"""Bounded least squares of a model against a recording, with the per-file sensor offsets
profiled out (they are nuisance parameters, never physics). The Jacobian's columns are
simulated together in one batch; parameters are fitted in scaled units."""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from typing import Callable, Mapping, Optional, Sequence

import numpy as np
from numpy.typing import NDArray

from ..recording import Recording
from .case_model import CaseSimulator, ModelSpec
from .segments import segment_starts

Setter = Callable[[dict, dict, float], None]


def set_param(name: str) -> Setter:
    def setter(params: dict, effects: dict, value: float) -> None:
        params[name] = value
    return setter


def set_effect(name: str) -> Setter:
    def setter(params: dict, effects: dict, value: float) -> None:
        effects[name] = value
    return setter


@dataclass(frozen=True)
class FreeParam:
    """A fitted quantity: value = x0 + scale u (or x0 exp(scale u) when `log`), u bounded."""

    name: str
    x0: float
    lower: float
    upper: float
    scale: float
    setter: Setter = field(compare=False, repr=False)
    log: bool = False
    unit: str = ""

    def value(self, u: float) -> float:
        return self.x0 * math.exp(self.scale * u) if self.log else self.x0 + self.scale * u

    def u_of(self, value: float) -> float:
        return math.log(value / self.x0) / self.scale if self.log else (value - self.x0) / self.scale

    def u_bounds(self) -> tuple[float, float]:
        return self.u_of(self.lower), self.u_of(self.upper)

    def at(self, value: float) -> "FreeParam":
        """The same parameter, centred on `value` (a new starting point)."""
        v = min(max(value, self.lower), self.upper)
        return replace(self, x0=v if not (self.log and v <= 0) else self.x0)


@dataclass
class FitResult:
    """Outcome of a fit; `chi2` is in units of the noise variance (sum of squared residuals / σ²)."""

    values: dict[str, float]
    std: dict[str, float]
    chi2: float
    n: int
    residuals: list[NDArray[np.float64]]  #: per experiment, offsets removed [m]
    offsets: list[float]  #: fitted position offset per segment (or experiment) [m]
    spec: ModelSpec
    nfev: int
    success: bool
    message: str
    #: correlation of the fitted parameters (from the Jacobian at the optimum)
    corr: dict[str, dict[str, float]] = field(default_factory=dict)

    @property
    def rms(self) -> float:
        return math.sqrt(sum(float(np.sum(r * r)) for r in self.residuals) / self.n)


def apply(base: ModelSpec, free: Sequence[FreeParam], u: NDArray[np.float64]) -> ModelSpec:
    params, effects = dict(base.params), dict(base.effects)
    for f, ui in zip(free, u):
        f.setter(params, effects, f.value(float(ui)))
    return ModelSpec(base.structure, params, effects)


class Objective:
    """Residuals in noise units for a recording over the experiments listed and the first
    `cycles` drive cycles of each (None: everything). With `segmented` (the default) every drive
    cycle's segment gets its own position offset (multiple shooting by translation, see
    :mod:`.segments`); otherwise one offset per experiment (single shooting)."""

    def __init__(self, recording: Recording, simulator: CaseSimulator, sigma: float,
                 experiments: Optional[Sequence[int]] = None, cycles: Optional[int] = None,
                 segmented: bool = True) -> None:
        self.recording = recording
        self.sim = simulator
        self.sigma = sigma
        self.cycles = cycles
        self.segmented = segmented
        self.experiments = list(range(len(recording.experiments))) if experiments is None else list(experiments)
        self.samples = {j: simulator.horizon(j, cycles)[1] for j in self.experiments}
        self.n = sum(self.samples.values())
        self.starts = {j: (segment_starts(recording.experiments[j], recording.sample_rate_Hz, self.samples[j])
                           if segmented else [0]) for j in self.experiments}
        #: nuisance offsets fitted with every model (one per segment, or per experiment)
        self.n_offsets = sum(len(s) for s in self.starts.values())
        self._bad = 1e3  # residual (noise units) given to samples of a diverged run

    def with_cycles(self, cycles: Optional[int]) -> "Objective":
        return Objective(self.recording, self.sim, self.sigma, self.experiments, cycles, self.segmented)

    def single_shooting(self) -> "Objective":
        """The same comparison with one offset per experiment (a slip event shifts the rest)."""
        return Objective(self.recording, self.sim, self.sigma, self.experiments, self.cycles, False)

    def predict(self, specs: Sequence[ModelSpec], retries: int = 2) -> list[list[NDArray[np.float64]]]:
        return self.sim.predict(specs, self.cycles, retries)

    def profiled(self, preds: Sequence[NDArray[np.float64]]) -> tuple[list[NDArray[np.float64]], list[float]]:
        """Residuals [m] with the best offset removed, and those offsets [m]."""
        res, offs = [], []
        for j in self.experiments:
            d = self.recording.experiments[j].x[: self.samples[j]] - preds[j]
            if not np.all(np.isfinite(d)):
                res.append(np.full(d.size, self._bad * self.sigma))
                offs.extend([math.nan] * len(self.starts[j]))
                continue
            r = np.empty_like(d)
            bounds = self.starts[j] + [d.size]
            for a, b in zip(bounds[:-1], bounds[1:]):
                o = float(d[a:b].mean())
                r[a:b] = d[a:b] - o
                offs.append(o)
            res.append(r)
        return res, offs

    def vector(self, preds: Sequence[NDArray[np.float64]]) -> NDArray[np.float64]:
        res, _ = self.profiled(preds)
        return np.concatenate(res) / self.sigma

    def chi2(self, spec: ModelSpec) -> float:
        v = self.vector(self.predict([spec])[0])
        return float(v @ v)


def fit(objective: Objective, base: ModelSpec, free: Sequence[FreeParam], *, max_nfev: int = 40,
        fd_step: float = 1e-3, progress: Optional[Callable[[], None]] = None) -> FitResult:
    """Least squares over `free` (trust-region reflective, bounded), from u = 0."""
    from scipy.optimize import least_squares  # lazily: it is most of `import idm_rs`'s time

    sim = objective.sim
    cache: dict[bytes, NDArray[np.float64]] = {}

    def fun(u: NDArray[np.float64]) -> NDArray[np.float64]:
        key = u.tobytes()
        if key not in cache:
            cache.clear()
            cache[key] = objective.vector(objective.predict([apply(base, free, u)])[0])
        if progress:
            progress()
        return cache[key]

    lo = np.array([f.u_bounds()[0] for f in free])
    hi = np.array([f.u_bounds()[1] for f in free])

    def jac(u: NDArray[np.float64]) -> NDArray[np.float64]:
        r0 = fun(u)
        specs, steps = [], []
        for j in range(len(free)):
            h = fd_step if u[j] + fd_step <= hi[j] else -fd_step  # stay inside the bounds
            uj = u.copy()
            uj[j] += h
            specs.append(apply(base, free, uj))
            steps.append(h)
        preds = objective.predict(specs)
        cols = [(objective.vector(p) - r0) / h for p, h in zip(preds, steps)]
        return np.stack(cols, axis=1)

    if not free:
        r = fun(np.zeros(0))
        res, offs = objective.profiled(objective.predict([base])[0])
        return FitResult({}, {}, float(r @ r), objective.n, res, offs, base, 1, True, "nothing to fit")
    u0 = np.clip(np.zeros(len(free)), lo, hi)
    sol = least_squares(fun, u0, jac=jac, bounds=(lo, hi), method="trf", x_scale=1.0, max_nfev=max_nfev,
                        xtol=1e-6, ftol=1e-8, gtol=1e-8)
    spec = apply(base, free, sol.x)
    preds = objective.predict([spec])[0]
    res, offs = objective.profiled(preds)
    chi2 = float(sum(np.sum(r * r) for r in res)) / objective.sigma**2
    # parameter uncertainty from the Jacobian at the optimum, scaled by the residual variance
    values, std = {}, {}
    J = sol.jac
    dof = max(objective.n - len(free) - objective.n_offsets, 1)
    s2 = max(chi2 / dof, 1.0)
    try:
        cov_u = np.linalg.pinv(J.T @ J) * s2
    except np.linalg.LinAlgError:
        cov_u = np.full((len(free), len(free)), np.nan)
    for j, f in enumerate(free):
        v = f.value(float(sol.x[j]))
        values[f.name] = v
        su = math.sqrt(max(cov_u[j, j], 0.0))
        std[f.name] = abs(v * f.scale * su) if f.log else abs(f.scale * su)
    d = np.sqrt(np.maximum(np.diag(cov_u), 1e-300))
    corr = {f.name: {g.name: float(np.clip(cov_u[a, b] / (d[a] * d[b]), -1.0, 1.0)) for b, g in enumerate(free)}
            for a, f in enumerate(free)}
    return FitResult(values, std, chi2, objective.n, res, offs, spec, int(sol.nfev), bool(sol.success), str(sol.message),
                     corr)


#: drive cycles fitted at each stage of a progressive fit (None: all). Stick-slip makes the
#: misfit a rugged function of the parameters over many cycles (a slip event more or less
#: shifts everything after it), but a smooth one over the first cycle; each stage starts in
#: the basin the shorter one found.
HORIZONS: tuple[Optional[int], ...] = (1, 2, None)


def fit_progressive(objective: Objective, base: ModelSpec, free: Sequence[FreeParam], *,
                    horizons: Sequence[Optional[int]] = HORIZONS, max_nfev: Sequence[int] = (20, 12, 12),
                    progress: Optional[Callable[[], None]] = None) -> FitResult:
    """`fit` over growing horizons, each stage started from the previous optimum (`max_nfev`
    per stage: the later stages start close to their optimum)."""
    current = list(free)
    result: Optional[FitResult] = None
    for k, nfev in zip(horizons, max_nfev):
        result = fit(objective.with_cycles(k), base, current, max_nfev=nfev, progress=progress)
        current = [f.at(result.values[f.name]) for f in current]
    assert result is not None
    return result
