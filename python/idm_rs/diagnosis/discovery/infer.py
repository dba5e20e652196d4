"""Step 1, the missing force inferred: an additive force on one body, piecewise linear in time,
fitted through the simulator on the engine's exact knot derivatives with a smoothing penalty
chosen by generalised cross-validation (:func:`infer_force`); or read directly off the
calibrated residual (:func:`direct_force`)."""

from __future__ import annotations

import math
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field
from typing import Any, Callable, Optional, Sequence, cast

import numpy as np
from numpy.typing import NDArray

from ...core import engine
from ...io.recording import Recording
from ..case_model import CaseSimulator, ModelSpec
from ..fitting import FreeParam, Objective
from ..thresholds import (
    FD_FORCE_STEP,
    FD_PARAM_STEP,
    FIT_DT,
    INFER_CONVERGED_GAIN,
    INFER_ITERATIONS,
    INFER_LM_START,
    INFER_MAX_TRIALS,
    INFER_METHOD,
    KNOTS_PER_CYCLE,
    SMOOTHING_GRID,
    START_FORCE,
)
from .library import Term, Trajectory, library_columns
from .linalg import lstsq, require_finite


@dataclass
class InferredForce:
    """An additive force on `body` per experiment, piecewise linear through `knots` [s] with
    `values` [N], that makes the calibrated model reproduce the recording."""

    body: str
    knots: list[NDArray[np.float64]]
    values: list[NDArray[np.float64]]
    smoothing: float  #: the penalty weight GCV chose (relative)
    chi2_before: float  #: calibrated model, no force (noise units)
    chi2_after: float  #: with the inferred force
    dof: float  #: effective number of parameters of the force (trace of the hat matrix)
    residuals: list[NDArray[np.float64]]  #: per experiment, offsets removed [m]
    #: d(residual / sigma) / d(force at knot) per experiment (samples x knots): what the data
    #: sees of the force
    jacobians: list[NDArray[np.float64]] = field(repr=False, default_factory=list)
    trajectories: list[Trajectory] = field(repr=False, default_factory=list)
    seconds: float = 0.0
    #: d(residual / sigma) / d(calibrated parameter, fit units) per experiment (samples x
    #: parameters) at the inferred force: the directions the refit can still move, which the
    #: form's regression projects out
    nuisance: list[NDArray[np.float64]] = field(repr=False, default_factory=list)
    #: the calibrated parameters as fitted jointly with the force
    parameters: dict[str, float] = field(default_factory=dict)
    #: their move from their centres [fit units], the columns of `nuisance`
    nuisance_u: Optional[NDArray[np.float64]] = field(default=None, repr=False, compare=False)
    #: the form reproduces the total correction, the force's effect plus the calibrated
    #: parameters' move (`nuisance` @ `nuisance_u`), instead of the force's alone
    with_nuisance: bool = False
    #: per experiment, the least-squares projector of samples onto the knots (made once)
    _projectors: dict[int, NDArray[np.float64]] = field(default_factory=dict, repr=False, compare=False)
    #: the library terms' exact effect on the readings at the inferred force's run:
    #: ``(terms, wavelength) -> per experiment (samples x terms)``, in the units of
    #: `jacobians` (None for a force made without the engine: then the library on the knots,
    #: pushed through `jacobians`)
    library_view: Optional[Callable[[Sequence["Term"], float], list[NDArray[np.float64]]]] = field(
        default=None, repr=False, compare=False)
    #: what the form must reproduce, per experiment (noise units), when it is not the force's
    #: effect: the direct regression's target is minus the calibrated residual itself
    #: (:func:`direct_force`), with white noise of unit variance in it
    target: Optional[list[NDArray[np.float64]]] = field(default=None, repr=False, compare=False)

    def on_knots(self, j: int, samples: NDArray[np.float64]) -> NDArray[np.float64]:
        """Samples of experiment j (samples x ...) as values on its knots, in least squares:
        a library function at the force's own resolution."""
        if j not in self._projectors:
            tr = self.trajectories[j]
            n = self.jacobians[j].shape[0]
            H = _hat_basis(self.knots[j], tr.t[:n])
            self._projectors[j] = lstsq(H.T @ H, H.T, "the knots' projector")[0]
        return self._projectors[j] @ samples

    @property
    def gain(self) -> float:
        """chi^2 the force removes, less twice its effective parameters (an AIC-like margin)."""
        return self.chi2_before - self.chi2_after - 2.0 * self.dof


def knot_times(rec: Recording, j: int, dt: float, per_cycle: int = KNOTS_PER_CYCLE) -> NDArray[np.float64]:
    """Knots of experiment j's force [s]: every 1/`per_cycle` drive cycle (a multiple of the
    fit step `dt`), from 0 through the end of the record."""
    e = rec.experiments[j]
    period = 1.0 / e.frequency_Hz if not e.is_sampled and e.frequency_Hz > 0 else e.duration / 10.0
    step = max(round(period / per_cycle / dt), 1) * dt
    n = int(math.ceil(e.duration / step - 1e-9))
    return np.arange(n + 1, dtype=np.float64) * step


def _second_differences(k: int) -> NDArray[np.float64]:
    d = np.zeros((max(k - 2, 0), k))
    for i in range(k - 2):
        d[i, i:i + 3] = (1.0, -2.0, 1.0)
    return d


def _given(params: dict[str, Optional[float]]) -> dict[str, float]:
    return {n: float(v) for n, v in params.items() if v is not None}


def run_with_force(rec: Recording, j: int, spec: ModelSpec, body: str, knots: NDArray[np.float64],
                   values: NDArray[np.float64], derivatives: bool = False, names: Optional[list[str]] = None,
                   effects: Optional[dict[str, float]] = None) -> tuple[dict[str, Any], Trajectory]:
    """Experiment j under `spec` with the force (knots, values) on `body`: the engine's output
    at the sample times (``reading``; with `derivatives`, ``sensitivities``: d reading / d force
    at every knot, samples x knots; with `names` instead, d reading / d each of those engine
    parameters; `effects` switches effects on beside `spec`'s, e.g. the library at zero
    coefficients for its derivatives) and the library's view of the trajectory."""
    e = rec.experiments[j]
    bt, bv = e.waveform.breakpoints()
    # the drive with a breakpoint at every sample (the same function): the adaptive method
    # lands on each sample time
    tt = np.union1d(bt, e.t)
    tt = tt[tt <= e.duration * (1 + 1e-12)]
    vv = np.interp(tt, bt, bv)
    config = spec.structure.config(first_step=1e-8, dt=1e-8, **INFER_METHOD)
    if derivatives:
        names = [f"f_ext[{k}]" for k in range(knots.size)]
    on = {n: float(v) for n, v in spec.effects.items() if v != 0.0}
    on.update(effects or {})
    raw = engine.simulate(_given(dict(spec.params)), on,
                          tt, vv, 0.0, float(e.duration), config, 1, False, None, names,
                          (np.ascontiguousarray(knots), np.ascontiguousarray(values, dtype=float), body))
    idx = np.minimum(np.searchsorted(raw["t"], e.t - 1e-12), raw["t"].size - 1)
    out = {k: raw[k][idx] for k in ("t", "reading", "nodes", "velocities", "friction", "voltage")}
    if names:
        out["sensitivities"] = raw["sensitivities"][idx]
    nodes, vel = out["nodes"], out["velocities"]
    volt = out["voltage"]
    t = out["t"]
    vs = float(spec.params.get("stribeck_velocity") or 1e-3)
    tr = Trajectory(t, nodes[:, 0], vel[:, 0], nodes[:, -1], vel[:, -1], out["friction"], volt,
                    np.gradient(volt, t), vs)
    return out, tr


def _hat_basis(knots: NDArray[np.float64], t: NDArray[np.float64]) -> NDArray[np.float64]:
    """Piecewise-linear hat functions of `knots` at times `t` (samples x knots)."""
    eye = np.eye(knots.size)
    return np.stack([np.interp(t, knots, eye[k]) for k in range(knots.size)], axis=1)


class _ForceFit:
    """The force inference's problem: runs of every experiment of `rec` with a force on `body`
    through each experiment's `knots` and the `free` calibrated parameters at `u` (fit units),
    their residuals and their derivatives (one thread per experiment)."""

    def __init__(self, rec: Recording, spec: ModelSpec, sigma: float, body: str, sim: CaseSimulator,
                 knots: list[NDArray[np.float64]], free: list[FreeParam], threads: int,
                 progress: Optional[Callable[..., Any]]) -> None:
        self.rec, self.spec, self.sigma, self.body, self.knots, self.free = rec, spec, sigma, body, knots, free
        self.n_exp = len(rec.experiments)
        self.objs = [Objective(rec, sim, sigma, [j]) for j in range(self.n_exp)]
        self.pool = ThreadPoolExecutor(max(1, threads))
        self.progress = progress

    def evaluate(self, vals: list[NDArray[np.float64]], uu: NDArray[np.float64], derivatives: bool) -> list[Any]:
        """Every experiment run with forces `vals` [N] at the knots and parameters `uu`; with
        `derivatives`, the readings' derivatives with respect to each knot ("sensitivities") and
        each parameter ("parameters"). A trial the device cannot follow is None."""
        from ..fitting import apply, engine_chain

        spec, free = self.spec, self.free
        at = apply(spec, free, uu) if free else spec
        uu = np.asarray(uu, dtype=float)
        pnames, chain = engine_chain(spec, free, uu) if (free and derivatives) else ([], None)
        return list(self.pool.map(lambda j: self._one(j, vals, uu, at, pnames, chain, derivatives),
                                  range(self.n_exp)))

    def _one(self, j: int, vals: list[NDArray[np.float64]], uu: NDArray[np.float64], at: ModelSpec,
             pnames: Sequence[str], chain: Optional[NDArray[np.float64]], derivatives: bool) -> Any:
        from ..fitting import apply, usable_derivative

        rec, body, knots, free = self.rec, self.body, self.knots, self.free
        k = knots[j].size
        names = [f"f_ext[{i}]" for i in range(k)] + list(pnames) if derivatives else None
        try:
            out, tr = run_with_force(rec, j, at, body, knots[j], vals[j], names=names)
        except engine.DivergenceError:
            if not derivatives:
                return None  # a trial the device cannot follow: rejected
            # the run stands but its derivative pass does not: differences for every knot
            out, tr = run_with_force(rec, j, at, body, knots[j], vals[j])
            out["sensitivities"] = np.full((out["reading"].size, k + len(pnames)), np.nan)
        if derivatives:
            sens = np.asarray(out["sensitivities"])
            out["sensitivities"] = np.ascontiguousarray(sens[:, :k])
            _repair_columns(out, lambda v: run_with_force(rec, j, at, body, knots[j], v)[0]["reading"], vals[j])
            par = sens[:, k:]
            dpar = (chain.T @ np.where(np.isfinite(par), par, 0.0).T if chain is not None  # i.e. free
                    else np.zeros((0, sens.shape[0])))
            if free and not usable_derivative(dpar, out["reading"]):
                # the parameters' derivatives blew up in a fast slip (as the fits' do at their
                # step): forward differences of runs, as the fits take them
                def reading(uu: NDArray[np.float64]) -> NDArray[np.float64]:
                    run = run_with_force(rec, j, apply(self.spec, free, uu), body, knots[j], vals[j])[0]
                    return cast("NDArray[np.float64]", run["reading"])

                dpar = _parameter_differences(reading, uu, out["reading"])
            out["parameters"] = dpar
        if self.progress:
            self.progress()
        return out, tr

    def residual(self, runs: list[Any]) -> tuple[list[NDArray[np.float64]], float]:
        """Per experiment the residual [m] (its offset profiled out), and chi^2 in all."""
        if any(r is None for r in runs):
            return [], math.inf
        res = []
        chi2 = 0.0
        for j, (out, _) in enumerate(runs):
            preds = [np.zeros(0)] * self.n_exp
            preds[j] = out["reading"][: self.objs[j].samples[j]]
            r, _ = self.objs[j].profiled(preds)
            res.append(r[0])
            chi2 += float(np.sum(r[0] ** 2)) / self.sigma**2
        return res, chi2

    def view(self, runs: list[Any]) -> tuple[list[NDArray[np.float64]], list[NDArray[np.float64]]]:
        """d(residual / sigma) / d(force at each knot) and / d(parameter, fit units), per
        experiment (samples x knots, samples x parameters)."""
        A: list[NDArray[np.float64]] = []
        S: list[NDArray[np.float64]] = []
        for j, (out, _) in enumerate(runs):
            n = self.objs[j].samples[j]
            for key, cols, into in (("sensitivities", self.knots[j].size, A), ("parameters", len(self.free), S)):
                d = np.asarray(out[key]).T if key == "sensitivities" else np.asarray(out[key])
                dpred = [np.zeros((cols, 0))] * self.n_exp
                dpred[j] = d[:, :n]
                into.append(self.objs[j].profiled_columns(dpred) if cols else np.zeros((n, 0)))
        return A, S


def infer_force(rec: Recording, spec: ModelSpec, sigma: float, body: str = "main", *, dt: float = FIT_DT,
                simulator: Optional[CaseSimulator] = None, per_cycle: int = KNOTS_PER_CYCLE,
                iterations: int = INFER_ITERATIONS, threads: int = 2, nuisance: Sequence[FreeParam] = (),
                progress: Optional[Callable[..., Any]] = None, trace: Optional[list[dict[str, float]]] = None
                ) -> InferredForce:
    """The additive force on `body` ("main" or "weight") that makes `spec` reproduce every
    experiment of `rec` (module docstring, step 1). `sigma`: the noise RMS [m]. `nuisance`:
    the calibrated parameters (centred on `spec`'s values), fitted jointly with the force: the
    calibration moved them to mimic the missing physics, and what they can absorb again is not
    the force's to explain (the smoothness penalty is on the force only, so a change the
    parameters can make is made by them). `trace` collects each trial step's figures."""
    import time

    from ..fitting import apply

    t0 = time.perf_counter()
    sim = simulator or CaseSimulator(rec, dt=dt)
    knots = [knot_times(rec, j, dt, per_cycle) for j in range(len(rec.experiments))]
    free = list(nuisance)
    problem = _ForceFit(rec, spec, sigma, body, sim, knots, free, threads, progress)
    try:
        values, u, res, chi2_0, chi2, lam_rel, dof, A, S, runs = _levenberg_marquardt(problem, iterations, trace)
    finally:
        problem.pool.shutdown()
    force = InferredForce(body, knots, values, lam_rel, chi2_0, chi2, dof, res, A, [tr for _, tr in runs],
                          time.perf_counter() - t0, S if free else [],
                          {f.name: f.value(float(x)) for f, x in zip(free, u)})
    force.nuisance_u = np.asarray(u, dtype=float) if free else None
    force.library_view = _LibraryView(problem, apply(spec, free, u) if free else spec, values, force, threads)
    return force


def _levenberg_marquardt(problem: _ForceFit, iterations: int, trace: Optional[list[dict[str, float]]]
                         ) -> tuple[Any, ...]:
    """Levenberg-Marquardt on the penalised misfit from START_FORCE everywhere and the
    parameters at their centres: the smoothing weight chosen by GCV on each linearisation, the
    damping (toward the current force) raised after a step that does not lower the misfit and
    lowered after one that does; trials are plain runs, derivatives are taken where a step is
    accepted. Returns (force values, parameters, residuals, chi^2 before, chi^2 after, the
    smoothing, its effective parameters, the knot and parameter views, the last runs)."""
    knots, free, sigma, n_exp = problem.knots, problem.free, problem.sigma, problem.n_exp
    values = [np.full(k.size, START_FORCE) for k in knots]
    D = [_second_differences(k.size) for k in knots]
    u = np.zeros(len(free))
    lo = np.array([f.u_bounds()[0] for f in free])
    hi = np.array([f.u_bounds()[1] for f in free])
    runs = problem.evaluate(values, u, True)
    A, S = problem.view(runs)
    res, chi2_0 = problem.residual(runs)
    chi2 = chi2_0
    lam_rel, dof = math.nan, 0.0
    mu = INFER_LM_START
    accepted = tries = 0
    while accepted < iterations and tries < INFER_MAX_TRIALS:
        b = [A[j] @ values[j] + S[j] @ u - res[j] / sigma for j in range(n_exp)]
        trial, du, lam_rel, dof, chi2_gn = _gcv_solve(A, b, D, mu, values, S, u)
        if chi2 - chi2_gn <= INFER_CONVERGED_GAIN * chi2 + dof:
            # not even the undamped step would gain more than what fitting noise with `dof`
            # parameters gains: converged
            break
        tu = np.clip(du, lo, hi) if free else u
        trial_res, trial_chi2 = problem.residual(problem.evaluate(trial, tu, False))
        tries += 1
        pred = sum(float(np.sum((A[j] @ (trial[j] - values[j]) + S[j] @ (tu - u) + res[j] / sigma) ** 2))
                   for j in range(n_exp))
        # how far the linearisation held (Levenberg-Marquardt's gain ratio): the damping follows
        # it (a damping raised 8x on every rejection, and convergence declared on the first
        # accepted step, however damped, that gained < 1 %, lowered chi^2 by 0-2 on systematic
        # residuals)
        rho = (chi2 - trial_chi2) / max(chi2 - pred, 1e-300)
        if trace is not None:
            trace.append({"chi2": chi2, "trial_chi2": trial_chi2, "predicted_chi2": pred,
                          "undamped_chi2": chi2_gn, "mu": mu, "rho": rho, "smoothing": lam_rel, "dof": dof,
                          "step_force": max(float(np.max(np.abs(trial[j] - values[j]))) for j in range(n_exp)),
                          "step_params": float(np.max(np.abs(tu - u))) if free else 0.0})
        if trial_chi2 < chi2:
            values, u, res, chi2 = trial, tu, trial_res, trial_chi2
            accepted += 1
            mu = mu / 8.0 if rho > 0.75 else (mu if rho > 0.25 else max(mu, 1e-3) * 4.0)
            runs = problem.evaluate(values, u, True)
            A, S = problem.view(runs)
        else:
            mu = max(mu, 1e-3) * 8.0
    return values, u, res, chi2_0, chi2, lam_rel, dof, A, S, runs


class _LibraryView:
    """The library terms' exact effect on the readings at the inferred force's run (the
    :attr:`InferredForce.library_view`): each term's coefficient seeded in the engine's
    ``library_force`` at `at` with the force through its knots, per experiment (samples x
    terms); a term is taken once (a periodic one once per wavelength)."""

    def __init__(self, problem: _ForceFit, at: ModelSpec, values: list[NDArray[np.float64]], force: InferredForce,
                 threads: int) -> None:
        self.problem, self.at, self.values, self.force, self.threads = problem, at, values, force, threads
        self.cache: dict[tuple[str, float], NDArray[np.float64]] = {}

    def __call__(self, terms: Sequence[Term], wavelength: float) -> list[NDArray[np.float64]]:
        pb = self.problem
        # a term's column depends on the wavelength only when it is periodic: the others are
        # taken once
        key = [(t.param, wavelength if t.periodic else 0.0) for t in terms]
        missing = [t for t, k in zip(terms, key) if k not in self.cache]
        if missing:
            with ThreadPoolExecutor(max(1, self.threads)) as lib_pool:
                cols = list(lib_pool.map(lambda j: self._columns(j, missing, wavelength), range(pb.n_exp)))
            for i, t in enumerate(missing):
                self.cache[(t.param, wavelength if t.periodic else 0.0)] = np.concatenate([c[:, i] for c in cols])
        sizes = np.cumsum([pb.objs[j].samples[j] for j in range(pb.n_exp)])[:-1]
        return np.split(np.stack([self.cache[k] for k in key], axis=1), sizes)

    def _columns(self, j: int, missing: list[Term], wavelength: float) -> NDArray[np.float64]:
        pb = self.problem
        names = [t.param for t in missing]
        extra = {"lib_wavelength": wavelength} if wavelength > 0 else {}
        n = pb.objs[j].samples[j]
        try:
            out, tr = run_with_force(pb.rec, j, self.at, pb.body, pb.knots[j], self.values[j], names=names,
                                     effects=extra)
            d = np.asarray(out["sensitivities"]).T[:, :n]
            bad = _blown_up(d, out["reading"][:n], library_columns(tr, missing, wavelength)[:n])
        except engine.DivergenceError:
            d, bad = np.full((len(names), n), np.nan), np.ones(len(names), dtype=bool)
        dpred = [np.zeros((len(names), 0))] * pb.n_exp
        dpred[j] = np.where(bad[:, None], 0.0, d)
        cols = pb.objs[j].profiled_columns(dpred)
        if np.any(bad):
            # a term whose exact derivative blew up is seen through the force's own (repaired)
            # knot derivatives instead
            cols[:, bad] = knot_view(self.force, j, [t for t, b in zip(missing, bad) if b], wavelength)
        return cols


def _blown_up(d: NDArray[np.float64], reading: NDArray[np.float64], functions: NDArray[np.float64]
              ) -> NDArray[np.bool_]:
    """Which library terms' reading derivatives (terms x samples [m per unit coefficient]) blew
    up: not finite, or beyond what the term's largest force along the run (`functions`, samples
    x terms [N per unit coefficient]) could do by the knots' own test (BLOWN_UP times the range
    of motion per newton, :func:`_repair_columns`). From the nominal values of a DPS 4 with a
    quadratic spring every term's derivative overflowed in one experiment (|column| ~ 1e154):
    the regression saw no term reproduce a force that took chi^2 from 3.06e6 to 1.9e4."""
    from ..thresholds import BLOWN_UP

    scale = BLOWN_UP * (float(np.ptp(reading)) + 1e-6) * np.max(np.abs(functions), axis=0)
    with np.errstate(invalid="ignore", over="ignore"):
        size = np.max(np.abs(d), axis=1) if d.size else np.zeros(d.shape[0])
    return cast("NDArray[np.bool_]", ~np.all(np.isfinite(d), axis=1) | ~(size <= scale))


def direct_force(rec: Recording, spec: ModelSpec, sigma: float, body: str = "main", *,
                 simulator: Optional[CaseSimulator] = None, nuisance: Sequence[FreeParam] = (),
                 progress: Optional[Callable[..., Any]] = None) -> InferredForce:
    """The direct regression's view of the residual (module docstring, step 2): no force is
    inferred; the form must reproduce minus the calibrated residual itself, each library term by
    its exact effect on the readings at the calibrated model. A force that changes faster than
    any knot spacing (friction periodic over a few micrometres, crossed within one slip) is then
    seen at the engine's full resolution. One knot per cycle (for the fallback view of a term
    whose derivatives cannot be taken)."""
    f = infer_force(rec, spec, sigma, body, simulator=simulator, per_cycle=1, iterations=0, nuisance=nuisance,
                    progress=progress)
    f.target = [-r / sigma for r in f.residuals]
    return f


def _parameter_differences(reading: Callable[[NDArray[np.float64]], NDArray[np.float64]], u: NDArray[np.float64],
                           base: NDArray[np.float64]) -> NDArray[np.float64]:
    """d(reading)/du by forward differences of runs (parameters x samples)."""
    rows = []
    for k in range(u.size):
        du = np.zeros(u.size)
        du[k] = FD_PARAM_STEP
        rows.append((reading(u + du) - base) / FD_PARAM_STEP)
    return np.array(rows).reshape(u.size, base.size)


def _repair_columns(out: dict[str, Any], reading: Callable[[NDArray[np.float64]], NDArray[np.float64]],
                    values: NDArray[np.float64]) -> int:
    """Replace, in place, each knot's derivative that blew up by a forward difference of
    runs; returns how many. A derivative through a state that sits exactly on a kink of the
    friction law (a body at rest, v1 = 0 exactly) follows the branch the value decided, which may
    be the wrong side for the perturbation and grow without bound (docs/SENSITIVITIES.md); a
    force of 1 N cannot move the reading by more than a few times the whole record's travel
    (the same test as the fits' :func:`~idm_rs.diagnosis.fitting.usable_derivative`).

    A derivative can also grow far short of that bound: through a fast slip the tangent pass
    may stay finite at 1e4 times what the runs themselves move, and those few columns then
    dominate the normal equations, so every damped step of the inference fails (a periodic
    friction on the LPS + h: the Gauss-Newton step predicted chi^2 315,163 -> 29,785, no trial
    gained). The columns that stand out are therefore checked against a difference, largest
    first, until one agrees within KNOT_DERIVATIVE_AGREE."""
    from ..thresholds import BLOWN_UP, KNOT_DERIVATIVE_AGREE

    S = out["sensitivities"]  # samples x knots [m/N]
    pred = out["reading"]
    limit = BLOWN_UP * (float(np.ptp(pred)) + 1e-6)
    bad = [k for k in range(S.shape[1]) if not np.all(np.isfinite(S[:, k])) or np.max(np.abs(S[:, k])) > limit]

    def difference(k: int) -> NDArray[np.float64]:
        v = values.copy()
        v[k] += FD_FORCE_STEP
        return cast("NDArray[np.float64]", (reading(v) - pred) / FD_FORCE_STEP)

    for k in bad:
        S[:, k] = difference(k)
    for k in np.argsort(-np.max(np.abs(S), axis=0), kind="stable"):
        if k in bad:
            continue
        d = difference(int(k))
        if np.linalg.norm(S[:, k]) <= KNOT_DERIVATIVE_AGREE * np.linalg.norm(d):
            break
        S[:, k] = d
        bad.append(int(k))
    return len(bad)


def _gcv_solve(A: list[NDArray[np.float64]], b: list[NDArray[np.float64]], D: list[NDArray[np.float64]],
               mu: float = 0.0, current: Optional[list[NDArray[np.float64]]] = None,
               S: Optional[list[NDArray[np.float64]]] = None, u: Optional[NDArray[np.float64]] = None
               ) -> tuple[list[NDArray[np.float64]], NDArray[np.float64], float, float, float]:
    """argmin over the knots c_j and the shared parameters v of
    sum_j ||A_j c_j + S_j v - b_j||^2 + lam ||D_j c_j||^2 + mu ||W (x - x_current)||^2
    (W^2 Marquardt's diagonal of the normal matrix, floored at its mean per block: a knot the
    readings barely see stays where it is unless the data ask), with lam by generalised
    cross-validation of the undamped problem (one lam for every experiment; the parameters are
    not penalised). Returns (c per experiment, v, lam relative to tr(A'A)/tr(D'D), the
    effective parameters tr(H), the undamped solution's ||A c + S v - b||^2)."""
    sizes = [a.shape[1] for a in A]
    kt = sum(sizes)
    p = 0 if S is None else S[0].shape[1]
    N = kt + p
    G = np.zeros((N, N))
    g = np.zeros(N)
    P = np.zeros((N, N))
    off = 0
    for j, a in enumerate(A):
        sl = slice(off, off + sizes[j])
        G[sl, sl] = a.T @ a
        g[sl] = a.T @ b[j]
        P[sl, sl] = D[j].T @ D[j]
        if p:
            assert S is not None  # p > 0
            G[sl, kt:] = a.T @ S[j]
            G[kt:, sl] = G[sl, kt:].T
            G[kt:, kt:] += S[j].T @ S[j]
            g[kt:] += S[j].T @ b[j]
        off += sizes[j]
    require_finite("the inferred force's normal equations", **{"J'J": G, "J'r": g})
    bb2 = sum(float(x @ x) for x in b)
    n = sum(x.size for x in b)
    scale = float(np.trace(G[:kt, :kt])) / max(float(np.trace(P)), 1e-300)
    best: Optional[tuple[float, float, NDArray[np.float64], float, float]] = None
    for rel in SMOOTHING_GRID:
        K = G + rel * scale * P
        try:
            sol = np.linalg.solve(K, np.column_stack([g, G]))
        except np.linalg.LinAlgError:
            sol = lstsq(K, np.column_stack([g, G]), "the inferred force's normal equations", None)[0]
        x, tr = sol[:, 0], float(np.trace(sol[:, 1:]))
        if tr >= n:
            continue
        rss = bb2 - 2.0 * float(x @ g) + float(x @ G @ x)
        score = n * max(rss, 0.0) / (n - tr) ** 2
        if best is None or score < best[0]:
            best = (score, float(rel), x, tr, max(rss, 0.0))
    assert best is not None
    x = best[2]
    if mu > 0.0 and current is not None:
        dg = np.diag(G).copy()
        floor = np.empty(N)
        floor[:kt] = float(np.mean(dg[:kt])) if kt else 0.0
        if p:
            floor[kt:] = float(np.mean(dg[kt:]))
        damp = mu * np.diag(dg + floor + 1e-300)
        parts = list(current)
        if p:
            assert u is not None  # the parameters' current values come with S
            parts.append(u)
        x0 = np.concatenate(parts)
        x = lstsq(G + best[1] * scale * P + damp, g + damp @ x0, "the inferred force's damped step", None)[0]
    cs = np.split(x[:kt], np.cumsum(sizes)[:-1])
    return list(cs), x[kt:], best[1], best[3], best[4]


def knot_view(force: InferredForce, j: int, terms: Sequence[Term], wavelength: float) -> NDArray[np.float64]:
    """The library's effect on experiment j's readings through the force's own derivatives:
    each function projected on the knots (the force's resolution), then pushed through
    `jacobians` (for a force made without the engine, or an experiment whose library
    derivatives could not be taken)."""
    A = force.jacobians[j]
    theta = library_columns(force.trajectories[j], terms, wavelength)[: A.shape[0]]
    return A @ force.on_knots(j, theta)
