"""Bounded least squares of a model against a recording, with the per-segment sensor offsets
profiled out (they are nuisance parameters, never physics). The Jacobian is exact: the engine's
sensitivities of the readings (:mod:`idm_rs` ``sensitivities=``) to the engine parameters the
free parameters move, chained through how they move them; parameters are fitted in scaled
units."""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from typing import Any, Callable, Optional, Sequence, cast

import numpy as np
from numpy.typing import NDArray

from ..io.recording import Recording
from .case_model import CaseSimulator, ModelSpec
from .measurement import Measurement, Profile
from .segments import segment_starts
from .thresholds import BLOWN_UP, CHAIN_STEP, FIT_HORIZONS, FTOL_CHI2, START_INSIDE

#: sets a free parameter's value in a model's (parameters, effects) as they are being built
Setter = Callable[[dict[str, Any], dict[str, float], float], None]


def set_param(name: str) -> Setter:
    def setter(params: dict[str, Any], effects: dict[str, float], value: float) -> None:
        params[name] = value
    return setter


def set_effect(name: str) -> Setter:
    def setter(params: dict[str, Any], effects: dict[str, float], value: float) -> None:
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
    #: the exact Jacobian at the optimum (residual samples x free parameters, fit units), when fitted
    jac: Optional[NDArray[np.float64]] = field(default=None, repr=False)

    @property
    def rms(self) -> float:
        return math.sqrt(sum(float(np.sum(r * r)) for r in self.residuals) / self.n)


def apply(base: ModelSpec, free: Sequence[FreeParam], u: NDArray[np.float64]) -> ModelSpec:
    params, effects = dict(base.params), dict(base.effects)
    for f, ui in zip(free, u):
        f.setter(params, effects, f.value(float(ui)))
    return ModelSpec(base.structure, params, effects)


def _engine_values(spec: ModelSpec) -> dict[str, float]:
    out = {n: float(v) for n, v in spec.params.items() if v is not None}
    out.update({n: float(v) for n, v in spec.effects.items()})
    return out


def usable_derivative(dpred: NDArray[np.float64], pred: NDArray[np.float64]) -> bool:
    """Whether an experiment's reading derivatives (fit units x samples) can be used: finite,
    and not grown without bound (an explicit step beyond the friction state's stability limit
    in a fast slip keeps the plain run bounded while its derivative grows exponentially; the
    engine reports the non-finite case, this catches the finite one)."""
    if not np.all(np.isfinite(dpred)):
        return False
    scale = float(np.ptp(pred)) + 1e-6 if pred.size else 1e-6
    return dpred.size == 0 or float(np.max(np.abs(dpred))) <= BLOWN_UP * scale



def engine_chain(base: ModelSpec, free: Sequence[FreeParam], u: NDArray[np.float64]
                 ) -> tuple[list[str], NDArray[np.float64]]:
    """The engine parameters the free parameters move at `u`, and d(engine value)/du
    (names x free): the chain from the fit's units to the engine's sensitivities. Setters may
    move several engine parameters (mu_k carrying a tied mu_s, the Stribeck excess setting
    mu_s from mu_k), so the map is taken from the setters themselves, not assumed."""
    cols = []
    for k in range(len(free)):
        up, dn = u.copy(), u.copy()
        up[k] += CHAIN_STEP
        dn[k] -= CHAIN_STEP
        a, b = _engine_values(apply(base, free, up)), _engine_values(apply(base, free, dn))
        cols.append({n: (a[n] - b.get(n, a[n])) / (2.0 * CHAIN_STEP) for n in a})
    names = sorted({n for c in cols for n, d in c.items() if d != 0.0})
    D = np.array([[c.get(n, 0.0) for c in cols] for n in names]).reshape(len(names), len(free))
    return names, D


def difference_columns(obj: "Objective", base: ModelSpec, free: Sequence[FreeParam], u: NDArray[np.float64],
                       experiments: Sequence[int], step: float = 1e-3, with_base: bool = False,
                       preds: Optional[Sequence[NDArray[np.float64]]] = None
                       ) -> tuple[Sequence[NDArray[np.float64]], dict[int, NDArray[np.float64]]]:
    """Forward-difference d(prediction)/du (free x samples) of `experiments` only, where the
    engine's derivative could not be used: one batch call with every stepped model (and the
    base model when `with_base`; else `preds` is the base). Returns (base predictions, columns),
    both indexed by experiment."""
    specs = [apply(base, free, u + step * np.eye(len(free))[k]) for k in range(len(free))]
    if with_base:
        specs.append(apply(base, free, u))
    fd = obj.sim.predict(specs, obj.cycles, experiments=experiments)
    at = fd[-1] if with_base else preds
    assert at is not None
    cols = {j: np.stack([(fd[k][j] - at[j]) / step for k in range(len(free))]) for j in experiments}
    return at, cols


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
        #: the sensor's measurement model (noise colour, nuisance columns, channel delay) the
        #: diagnosis learned and left on the recording; None: white noise, offsets only
        m = getattr(recording, "measurement", None)
        self.measurement: Optional[Measurement] = None if m is None or m.trivial else m
        self._profiles: dict[int, Profile] = {}
        if self.measurement is not None:
            for j in self.experiments:
                t = recording.experiments[j].t[: self.samples[j]]
                self._profiles[j] = Profile(self.measurement, t, self.starts[j])

    def with_cycles(self, cycles: Optional[int]) -> "Objective":
        return Objective(self.recording, self.sim, self.sigma, self.experiments, cycles, self.segmented)

    def single_shooting(self) -> "Objective":
        """The same comparison with one offset per experiment (a slip event shifts the rest)."""
        return Objective(self.recording, self.sim, self.sigma, self.experiments, self.cycles, False)

    def predict(self, specs: Sequence[ModelSpec], retries: int = 2) -> list[list[NDArray[np.float64]]]:
        return self.sim.predict(specs, self.cycles, retries)

    def predict_checked(self, spec: ModelSpec) -> tuple[list[NDArray[np.float64]], Optional[list[float]]]:
        """One model's readings and the RK4 step [s] each experiment's run finished at, None
        where one diverged (:meth:`CaseSimulator.predict_checked`): the readings then stand for
        the run a Jacobian at the same model would repeat (:meth:`jacobian`'s `at_steps`)."""
        preds, steps = self.sim.predict_checked([spec], self.cycles)
        return preds[0], steps[0]

    def profiled(self, preds: Sequence[NDArray[np.float64]]) -> tuple[list[NDArray[np.float64]], list[float]]:
        """Residuals [m] with the best offset removed, and those offsets [m]."""
        res, offs = [], []
        m = self.measurement
        for j in self.experiments:
            p = preds[j] if m is None else m.shifted(np.asarray(preds[j])[: self.samples[j]],
                                                     self.recording.sample_step)
            d = self.recording.experiments[j].x[: self.samples[j]] - p
            if not np.all(np.isfinite(d)):
                res.append(np.full(d.size, self._bad * self.sigma))
                offs.extend([math.nan] * len(self.starts[j]))
                continue
            if m is not None:
                # generalised least squares: whitened, the nuisances profiled out in that metric
                w, coef = self._profiles[j].residual(d)
                res.append(w)
                offs.extend(float(c) for c in coef[: len(self.starts[j])])
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

    def profiled_columns(self, dpred: Sequence[NDArray[np.float64]]) -> NDArray[np.float64]:
        """d(residual vector)/d(something) from d(prediction)/d(something) per experiment
        (columns x samples): the residual is data minus prediction minus each segment's mean,
        so a column is minus the prediction's derivative less its segment mean, in noise units."""
        blocks = []
        m = self.measurement
        for j in self.experiments:
            s = np.asarray(dpred[j])[:, : self.samples[j]]
            if m is not None:
                blocks.append(self._profiles[j].columns(m.shifted(s, self.recording.sample_step)))
                continue
            c = np.empty_like(s)
            bounds = self.starts[j] + [s.shape[1]]
            for a, b in zip(bounds[:-1], bounds[1:]):
                c[:, a:b] = s[:, a:b] - s[:, a:b].mean(axis=1, keepdims=True)
            blocks.append(c)
        return cast("NDArray[np.float64]", -np.concatenate(blocks, axis=1).T / self.sigma)

    def jacobian(self, base: ModelSpec, free: Sequence[FreeParam], u: NDArray[np.float64],
                 fd_step: float = 1e-3, unbounded: Optional[set[int]] = None,
                 at: Optional[Sequence[NDArray[np.float64]]] = None, at_steps: Optional[Sequence[float]] = None
                 ) -> tuple[NDArray[np.float64], NDArray[np.float64], int]:
        """(residual vector, its exact Jacobian in the fit units, simulations run) at `u`. An
        experiment whose derivatives could not be taken (the engine reports why: e.g. a fast
        slip beyond the friction state's RK4 stability limit at the fit step, where the plain
        run stays bounded but its derivative does not; see :func:`usable_derivative`) gets
        forward-difference columns and is added to `unbounded`; an experiment already in it gets
        them without trying the engine's derivative (a fit passes one set for all its
        Jacobians). Nothing is remembered beyond the set the caller passes: a blow-up at one
        model says nothing about another (kept on the simulator, it once made a fit's path
        depend on every fit run before it — RESULTS 15e). `at`: the plain predictions at `u`
        when the caller has them (a fit's last evaluation), so the differences need no base run;
        with `at_steps` (the RK4 step each of its runs finished at, :meth:`predict_checked`) the
        engine does not repeat that run either and takes only the derivative passes, each at its
        run's step (a fit's Jacobian is always taken where its last evaluation ran: a fifth of the
        Jacobian's cost, and for a run the engine had to retry at dt/2 also the run at the fit
        step that diverged)."""
        names, D = engine_chain(base, free, u)
        spec = apply(base, free, u)
        skip = unbounded if unbounded is not None else set()
        exact = [j for j in self.experiments if j not in skip]
        reuse = at is not None and at_steps is not None and bool(names)
        given = [list(at)] if reuse and at is not None else None
        steps = [list(at_steps)] if reuse and at_steps is not None else None
        pred_sets, sens_sets, _ = self.sim.predict_with_sensitivities([spec], names, self.cycles, experiments=exact,
                                                                      readings=given, steps=steps)
        preds, sens = list(pred_sets[0]), sens_sets[0]
        dpred: list[NDArray[np.float64]] = [np.zeros((len(free), 0))] * len(preds)
        bad = [j for j in self.experiments if j in skip]
        for j in exact:
            d = D.T @ sens[j] if len(names) else np.zeros((len(free), preds[j].size))
            if not np.all(np.isfinite(preds[j])):
                d = np.zeros((len(free), preds[j].size))  # a diverged run: a constant residual, no slope
            elif not usable_derivative(d, preds[j]):
                bad.append(j)
                skip.add(j)  # it will blow up again at the next parameters: differences from now on
            dpred[j] = d
        runs = 1
        if bad:
            base_preds, cols = difference_columns(self, base, free, u, bad, fd_step, with_base=at is None, preds=at)
            runs += len(free)
            for j in bad:
                preds[j], dpred[j] = base_preds[j], cols[j]
        r = self.vector(preds)
        # a step that diverged (or a base run that did) has no usable slope: zero, not NaN, so
        # the solver's factorisation never sees a non-finite entry
        dpred = [np.where(np.isfinite(d), d, 0.0) for d in dpred]
        return r, self.profiled_columns(dpred), runs


def inside_bounds(free: Sequence[FreeParam]) -> list[FreeParam]:
    """The free parameters re-centred at least START_INSIDE fit units inside their bounds.
    scipy's trust-region reflective solver first moves a start that lies on a bound (within
    1e-10) a hair inside, and then sizes its first trust region from that hair (|u0| / sqrt of
    the distance to the bound): from a calibration with one parameter at its bound the first
    step was 8e-11 fit units, each later one twice the last, and the fit stopped at its start
    (measured on a two-effect device: the spring's fit from the null's second optimum, which had
    the friction stiffness at its bound, ended where it began after 2 of its 16 evaluations).
    Centred strictly inside, the start is u = 0 and the first trust region one fit unit."""
    out = []
    for f in free:
        lo, hi = f.u_bounds()
        u = min(max(0.0, lo + START_INSIDE), hi - START_INSIDE) if hi - lo > 2.0 * START_INSIDE else 0.0
        out.append(f.at(f.value(u)) if u != 0.0 else f)
    return out


def fit(objective: Objective, base: ModelSpec, free: Sequence[FreeParam], *, max_nfev: int = 40,
        fd_step: float = 1e-3, progress: Optional[Callable[[], None]] = None) -> FitResult:
    """Least squares over `free` (trust-region reflective, bounded, scipy), from u = 0, on the
    exact Jacobian (:meth:`Objective.jacobian`; `fd_step` only where the engine could not take
    an experiment's derivatives)."""
    from scipy.optimize import least_squares  # lazily: it is most of `import idm_rs`'s time

    free = inside_bounds(free)
    # the last evaluation's residual vector and predictions: the Jacobian at that point takes
    # its differences' base from them, and the result its residuals
    cache: dict[bytes, tuple[NDArray[np.float64], list[NDArray[np.float64]], Optional[list[float]]]] = {}
    unbounded: set[int] = set()  # experiments whose derivatives blew up in this fit (see Objective.jacobian)

    def fun(u: NDArray[np.float64]) -> NDArray[np.float64]:
        key = u.tobytes()
        if key not in cache:
            cache.clear()
            preds, steps = objective.predict_checked(apply(base, free, u))
            cache[key] = (objective.vector(preds), preds, steps)
        if progress:
            progress()
        return cache[key][0]

    lo = np.array([f.u_bounds()[0] for f in free])
    hi = np.array([f.u_bounds()[1] for f in free])

    def jac(u: NDArray[np.float64]) -> NDArray[np.float64]:
        hit = cache.get(u.tobytes())
        _, J, _ = objective.jacobian(base, free, u, fd_step, unbounded, at=hit[1] if hit else None,
                                     at_steps=hit[2] if hit else None)
        if progress:
            progress()
        return J

    if not free:
        r = fun(np.zeros(0))
        res, offs = objective.profiled(objective.predict([base])[0])
        return FitResult({}, {}, float(r @ r), objective.n, res, offs, base, 1, True, "nothing to fit")
    u0 = np.clip(np.zeros(len(free)), lo, hi)
    sol = least_squares(fun, u0, jac=jac, bounds=(lo, hi), method="trf", x_scale=1.0, max_nfev=max_nfev,
                        xtol=1e-6, ftol=FTOL_CHI2 / max(objective.n, 1), gtol=1e-8)
    spec = apply(base, free, sol.x)
    hit = cache.get(np.asarray(sol.x).tobytes())
    preds = hit[1] if hit else objective.predict([spec])[0]
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
    return FitResult(values, std, chi2, objective.n, res, offs, spec, int(sol.nfev), bool(sol.success),
                     str(sol.message), corr, np.asarray(J))


def fit_progressive(objective: Objective, base: ModelSpec, free: Sequence[FreeParam], *,
                    horizons: Sequence[Optional[int]] = FIT_HORIZONS, max_nfev: Sequence[int] = (20, 12, 12),
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
