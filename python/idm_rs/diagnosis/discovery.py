"""Beyond the catalogue: find a force the model lacks in the data, name its form, model it.

When no catalogue effect explains a systematic residual, three steps (docs/DIAGNOSIS.md,
"Discovery"):

1. **The missing force, inferred** (:func:`infer_force`). With the calibrated model, an additive
   force on the main body (and, as the second hypothesis, on the weight) as a piecewise-linear
   function of time (knots every 1/``KNOTS_PER_CYCLE`` of a drive cycle), fitted through the
   simulator: Gauss-Newton on the engine's exact derivatives of the readings with respect to
   the force at every knot (``ExternalForce``, sensitivities ``f_ext[k]``), with a penalty on
   the force's second differences whose weight generalised cross-validation chooses at every
   iteration.
2. **Its form, found** (:func:`find_terms`). Sparse regression (scikit-learn's orthogonal
   matching pursuit) of the inferred force on a library of candidate functions of the
   simulated states and the input, in the metric of the data: the inferred force's effect on
   the readings against each library term's, both exact derivatives of the readings at the
   inferred force's run (the term's coefficient seeded in the engine's ``library_force``), so
   a term is judged by the readings it would explain, at the engine's full resolution (the
   friction force jumps within a slip, faster than the knots), not by the force where the
   readings cannot see it (a stuck body hides the force on it). The number of terms and the
   wavelength of the periodic terms are chosen by cross-validation across experiments (leave
   one experiment out).
3. **The term, modelled** (:func:`discover`). The found terms become the engine's
   ``library_force`` (or ``library_force_weight``) effect with their coefficients free; the
   whole model (calibrated subset too) is refitted on exact Jacobians; the verdict is
   ``discovered`` only when the refit improves BIC over the calibrated null by the catalogue's
   threshold and the held-out experiment's prediction improves.
"""

from __future__ import annotations

import math
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field, replace
from typing import Any, Callable, Optional, Sequence

import numpy as np
from numpy.typing import NDArray

from .. import engine
from ..recording import Recording
from .case_model import FIT_DT, CaseSimulator, ModelSpec
from .fitting import FitResult, FreeParam, Objective, fit, set_effect
from .thresholds import BIC_THRESHOLD, NOISE_RATIO_OK

#: knots of the inferred force per drive cycle: resolves the slow phase's shape and the fast
#: edge to its own length (0.5 ms at 100 Hz)
KNOTS_PER_CYCLE = 20
#: accepted Levenberg-Marquardt steps of the force inference, at most (the force enters
#: linearly; what is left is the stick-slip's own nonlinearity), and trial steps in all
ITERATIONS = 8
MAX_TRIALS = 16
#: the first damping (relative to the diagonal of J'J), and the relative chi^2 gain below which
#: the inference has converged (beyond the `dof` units that fitting noise gains): judged on the
#: undamped linear step, so a damped step's small gain is never taken for convergence
LM_START = 0.01
CONVERGED_GAIN = 0.01
#: smoothing weights tried by generalised cross-validation, relative to tr(J'J)/tr(D'D)
SMOOTHING_GRID = np.logspace(-8, 2, 41)
#: most library terms a discovered force may have
MAX_TERMS = 4
#: wavelengths [m] of the periodic library terms tried (their fit refines the one chosen)
WAVELENGTHS = np.geomspace(2e-6, 200e-6, 25)
#: a periodic term must lower the cross-validated error by this factor below the best
#: non-periodic form: the wavelength scan is itself a choice the data must pay for
PERIODIC_GAIN = 0.9
#: a term more must lower the cross-validated error by this factor and by TERM_SHARE of the
#: force's own effect
TERM_GAIN = 0.9
TERM_SHARE = 0.02
#: a found term whose refitted coefficient is within this many standard deviations of zero is
#: dropped unless the model without it is worse by BIC_THRESHOLD
PRUNE_Z = 5.0
#: a library term whose effect keeps less than this share of its size once the calibrated
#: parameters' directions are projected out is their alias (left out of the regression)
ALIAS_SHARE = 0.05
#: a form must predict the held-out experiments' force effect to within this share of it
#: (cross-validated error relative to the force's own effect): at least half explained
FORM_CV_MAX = 0.5
#: rounds of pruning (each drops every weak term at once and refits)
PRUNE_ROUNDS = 3
#: evaluations of the refit with the found terms
REFIT_NFEV = 25


# ---------------------------------------------------------------------------------------------
# Linear algebra that names its failures
# ---------------------------------------------------------------------------------------------

class NumericalFailure(RuntimeError):
    """A linear system of discovery that is not finite or cannot be solved. It is named in the
    report as what stopped a step of discovery, never turned into a verdict on the physics."""


def _require_finite(stage: str, **arrays: NDArray[np.float64]) -> None:
    for name, a in arrays.items():
        a = np.asarray(a)
        bad = int(a.size - np.count_nonzero(np.isfinite(a)))
        if bad:
            raise NumericalFailure(f"{stage}: {bad} of {a.size} entries of {name} {a.shape} are not finite")


#: relative size of a pivot below which a column counts as dependent on the others (the
#: library's columns and the knots' bases; normal equations are solved at machine precision)
RANK_TOLERANCE = 1e-12


def _lstsq(A: NDArray[np.float64], b: NDArray[np.float64], stage: str, cond: Optional[float] = RANK_TOLERANCE
           ) -> tuple[NDArray[np.float64], int]:
    """Least squares by QR with column pivoting (LAPACK gelsy: no SVD iteration that can fail to
    converge), inputs checked finite; returns (solution, numerical rank at `cond`)."""
    import scipy.linalg

    _require_finite(stage, A=A, b=b)
    try:
        x, _, rank, _ = scipy.linalg.lstsq(A, b, cond=cond, lapack_driver="gelsy")
    except (np.linalg.LinAlgError, ValueError) as e:
        raise NumericalFailure(f"{stage}: {e}") from e
    return x, int(rank)


# ---------------------------------------------------------------------------------------------
# The library
# ---------------------------------------------------------------------------------------------

@dataclass(frozen=True)
class Term:
    """One library function: its engine coefficient, its symbol and what it reads."""

    param: str  #: the engine's effect parameter (its coefficient)
    symbol: str  #: as printed, e.g. "v1|v1|"
    unit: str  #: the coefficient's unit
    variable: str  #: the state it depends on, for the report ("x1", "v1", "x1 - x2", ...)
    periodic: bool = False


MAIN_TERMS: tuple[Term, ...] = (
    Term("lib_x1", "x1", "N/m", "x1"),
    Term("lib_v1", "v1", "N s/m", "v1"),
    Term("lib_dx", "x1 - x2", "N/m", "x1 - x2"),
    Term("lib_dv", "v1 - v2", "N s/m", "v1 - v2"),
    Term("lib_sgn", "sgn v1", "N", "v1"),
    Term("lib_abs", "|v1|", "N s/m", "v1"),
    Term("lib_vv", "v1|v1|", "N s^2/m^2", "v1"),
    Term("lib_volt", "V", "N/V", "V"),
    Term("lib_dvolt", "dV/dt", "N s/V", "V"),
    Term("lib_t", "t", "N/s", "t"),
    Term("lib_x1sq", "x1^2", "N/m^2", "x1"),
    Term("lib_x1cube", "x1^3", "N/m^3", "x1"),
    Term("lib_ff", "Ff", "1", "Ff"),
    Term("lib_sin", "sin(2 pi x1/lambda)", "N", "x1", True),
    Term("lib_cos", "cos(2 pi x1/lambda)", "N", "x1", True),
    Term("lib_ff_sin", "Ff sin(2 pi x1/lambda)", "1", "x1", True),
    Term("lib_ff_cos", "Ff cos(2 pi x1/lambda)", "1", "x1", True),
)

WEIGHT_TERMS: tuple[Term, ...] = (
    Term("libw_x2", "x2", "N/m", "x2"),
    Term("libw_v2", "v2", "N s/m", "v2"),
    Term("libw_dx", "x2 - x1", "N/m", "x2 - x1"),
    Term("libw_dv", "v2 - v1", "N s/m", "v2 - v1"),
    Term("libw_sgn", "sgn v2", "N", "v2"),
    Term("libw_vv", "v2|v2|", "N s^2/m^2", "v2"),
    Term("libw_volt", "V", "N/V", "V"),
    Term("libw_dvolt", "dV/dt", "N s/V", "V"),
)


@dataclass
class Trajectory:
    """What the library reads along one experiment's run, at the sample times."""

    t: NDArray[np.float64]
    x1: NDArray[np.float64]
    v1: NDArray[np.float64]
    x2: NDArray[np.float64]
    v2: NDArray[np.float64]
    ff: NDArray[np.float64]
    volt: NDArray[np.float64]
    dvolt: NDArray[np.float64]
    vs: float  #: the Stribeck velocity the smoothed sign uses [m/s]


def library_columns(tr: Trajectory, terms: Sequence[Term], wavelength: float) -> NDArray[np.float64]:
    """Each term's function along the trajectory (samples x terms), as the engine computes it
    (``effects.rs``: sgn smoothed as tanh(v/v_s); the periodic terms at `wavelength`)."""
    k = 2.0 * math.pi / wavelength if wavelength > 0 else 0.0
    s, c = np.sin(k * tr.x1), np.cos(k * tr.x1)
    f = {
        "lib_x1": tr.x1, "lib_v1": tr.v1, "lib_dx": tr.x1 - tr.x2, "lib_dv": tr.v1 - tr.v2,
        "lib_sgn": np.tanh(tr.v1 / tr.vs), "lib_abs": np.abs(tr.v1), "lib_vv": tr.v1 * np.abs(tr.v1),
        "lib_volt": tr.volt, "lib_dvolt": tr.dvolt, "lib_t": tr.t, "lib_x1sq": tr.x1**2, "lib_x1cube": tr.x1**3,
        "lib_ff": tr.ff, "lib_sin": s, "lib_cos": c, "lib_ff_sin": tr.ff * s, "lib_ff_cos": tr.ff * c,
        "libw_x2": tr.x2, "libw_v2": tr.v2, "libw_dx": tr.x2 - tr.x1, "libw_dv": tr.v2 - tr.v1,
        "libw_sgn": np.tanh(tr.v2 / tr.vs), "libw_vv": tr.v2 * np.abs(tr.v2), "libw_volt": tr.volt,
        "libw_dvolt": tr.dvolt,
    }
    return np.stack([f[t.param] for t in terms], axis=1)


# ---------------------------------------------------------------------------------------------
# Step 1: the inferred force
# ---------------------------------------------------------------------------------------------

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
            self._projectors[j] = _lstsq(H.T @ H, H.T, "the knots' projector")[0]
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


def _given(params: dict) -> dict[str, float]:
    return {n: float(v) for n, v in params.items() if v is not None}


#: the integrator of the force inference: Dormand-Prince, landing on every sample time. RK4 at
#: the fit step lets the derivatives grow without bound in fast slips (the friction state's
#: stability limit); the adaptive step keeps both the run and its derivatives stable. Its knot
#: derivatives agree with RK4's at dt = 1e-8 s (where RK4's are stable) to 3 % on the test
#: cases, in 0.06 s per 8 knots of a 42 ms record (Rodas4's did not, through the kinks).
INFER_METHOD = dict(method="dopri5", rtol=1e-8, atol=1e-8)
#: the force the inference starts from [N], everywhere: not exactly zero, so a body at rest is
#: not exactly on the friction law's kinks (v1 = 0, Fh = 0), where a derivative is one-sided and
#: the side the value picks may be the wrong one for the perturbation (docs/SENSITIVITIES.md);
#: a micronewton moves the body by ~1e-16 m
START_FORCE = 1e-6


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


def infer_force(rec: Recording, spec: ModelSpec, sigma: float, body: str = "main", *, dt: float = FIT_DT,
                simulator: Optional[CaseSimulator] = None, per_cycle: int = KNOTS_PER_CYCLE,
                iterations: int = ITERATIONS, threads: int = 2, nuisance: Sequence[FreeParam] = (),
                progress: Optional[Callable[..., Any]] = None, trace: Optional[list[dict[str, float]]] = None
                ) -> InferredForce:
    """The additive force on `body` ("main" or "weight") that makes `spec` reproduce every
    experiment of `rec` (module docstring, step 1). `sigma`: the noise RMS [m]. `nuisance`:
    the calibrated parameters (centred on `spec`'s values), fitted jointly with the force: the
    calibration moved them to mimic the missing physics, and what they can absorb again is not
    the force's to explain (the smoothness penalty is on the force only, so a change the
    parameters can make is made by them)."""
    import time

    from .fitting import apply, engine_chain, usable_derivative

    t0 = time.perf_counter()
    sim = simulator or CaseSimulator(rec, dt=dt)
    n_exp = len(rec.experiments)
    objs = [Objective(rec, sim, sigma, [j]) for j in range(n_exp)]
    knots = [knot_times(rec, j, dt, per_cycle) for j in range(n_exp)]
    values = [np.full(k.size, START_FORCE) for k in knots]
    D = [_second_differences(k.size) for k in knots]
    free = list(nuisance)
    u = np.zeros(len(free))
    lo = np.array([f.u_bounds()[0] for f in free])
    hi = np.array([f.u_bounds()[1] for f in free])
    pool = ThreadPoolExecutor(max(1, threads))

    def evaluate(vals: list[NDArray[np.float64]], uu: NDArray[np.float64], derivatives: bool):
        at = apply(spec, free, uu) if free else spec
        uu = np.asarray(uu, dtype=float)
        pnames, chain = engine_chain(spec, free, uu) if (free and derivatives) else ([], None)

        def one(j: int):
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
                _repair_columns(out, lambda v: run_with_force(rec, j, at, body, knots[j], v)[0]["reading"],
                                vals[j])
                par = sens[:, k:]
                dpar = (chain.T @ np.where(np.isfinite(par), par, 0.0).T if chain is not None  # i.e. free
                        else np.zeros((0, sens.shape[0])))
                if free and not usable_derivative(dpar, out["reading"]):
                    # the parameters' derivatives blew up in a fast slip (as the fits' do at their
                    # step): forward differences of runs, as the fits take them
                    dpar = _parameter_differences(
                        lambda uu: run_with_force(rec, j, apply(spec, free, uu), body, knots[j], vals[j])[0]["reading"],
                        uu, out["reading"])
                out["parameters"] = dpar
            if progress:
                progress()
            return out, tr
        return list(pool.map(one, range(n_exp)))

    def residual(runs) -> tuple[list[NDArray[np.float64]], float]:
        if any(r is None for r in runs):
            return [], math.inf
        res = []
        chi2 = 0.0
        for j, (out, _) in enumerate(runs):
            preds = [np.zeros(0)] * n_exp
            preds[j] = out["reading"][: objs[j].samples[j]]
            r, _ = objs[j].profiled(preds)
            res.append(r[0])
            chi2 += float(np.sum(r[0] ** 2)) / sigma**2
        return res, chi2

    def view(runs) -> tuple[list[NDArray[np.float64]], list[NDArray[np.float64]]]:
        """d(residual / sigma) / d(force at each knot) and / d(parameter, fit units), per
        experiment (samples x knots, samples x parameters)."""
        A: list[NDArray[np.float64]] = []
        S: list[NDArray[np.float64]] = []
        for j, (out, _) in enumerate(runs):
            n = objs[j].samples[j]
            for key, cols, into in (("sensitivities", knots[j].size, A), ("parameters", len(free), S)):
                d = np.asarray(out[key]).T if key == "sensitivities" else np.asarray(out[key])
                dpred = [np.zeros((cols, 0))] * n_exp
                dpred[j] = d[:, :n]
                into.append(objs[j].profiled_columns(dpred) if cols else np.zeros((n, 0)))
        return A, S

    try:
        runs = evaluate(values, u, True)
        A, S = view(runs)
        res, chi2_0 = residual(runs)
        chi2 = chi2_0
        lam_rel, dof = math.nan, 0.0
        # Levenberg-Marquardt on the penalised misfit: the smoothing weight chosen by GCV on
        # each linearisation, the damping (toward the current force) raised after a step that
        # does not lower the misfit and lowered after one that does; trials are plain runs,
        # derivatives are taken where a step is accepted
        mu = LM_START
        accepted = tries = 0
        while accepted < iterations and tries < MAX_TRIALS:
            b = [A[j] @ values[j] + S[j] @ u - res[j] / sigma for j in range(n_exp)]
            trial, du, lam_rel, dof, chi2_gn = _gcv_solve(A, b, D, mu, values, S, u)
            if chi2 - chi2_gn <= CONVERGED_GAIN * chi2 + dof:
                # not even the undamped step would gain more than what fitting noise with `dof`
                # parameters gains: converged
                break
            tu = np.clip(du, lo, hi) if free else u
            trial_res, trial_chi2 = residual(evaluate(trial, tu, False))
            tries += 1
            pred = sum(float(np.sum((A[j] @ (trial[j] - values[j]) + S[j] @ (tu - u) + res[j] / sigma) ** 2))
                       for j in range(n_exp))
            # how far the linearisation held (Levenberg-Marquardt's gain ratio): the damping
            # follows it. Before issue 31 the damping rose 8x on every rejection and the first
            # accepted step, however damped, that gained < 1 % ended the inference as
            # "converged": on systematic residuals it then lowered chi^2 by 0-2
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
                runs = evaluate(values, u, True)
                A, S = view(runs)
            else:
                mu = max(mu, 1e-3) * 8.0
    finally:
        pool.shutdown()
    force = InferredForce(body, knots, values, lam_rel, chi2_0, chi2, dof, res, A, [tr for _, tr in runs],
                          time.perf_counter() - t0, S if free else [],
                          {f.name: f.value(float(x)) for f, x in zip(free, u)})
    at = apply(spec, free, u) if free else spec
    cache: dict[tuple[str, float], NDArray[np.float64]] = {}

    def library_view(terms: Sequence[Term], wavelength: float) -> list[NDArray[np.float64]]:
        # a term's column depends on the wavelength only when it is periodic: the others are
        # taken once
        key = [(t.param, wavelength if t.periodic else 0.0) for t in terms]
        missing = [t for t, k in zip(terms, key) if k not in cache]
        if missing:
            names = [t.param for t in missing]
            extra = {"lib_wavelength": wavelength} if wavelength > 0 else {}

            def one(j: int) -> NDArray[np.float64]:
                n = objs[j].samples[j]
                try:
                    out, _ = run_with_force(rec, j, at, body, knots[j], values[j], names=names, effects=extra)
                    d = np.asarray(out["sensitivities"]).T[:, :n]
                except engine.DivergenceError:
                    d = np.full((len(names), n), np.nan)
                if not np.all(np.isfinite(d)):
                    return _knot_view(force, j, missing, wavelength)
                dpred = [np.zeros((len(names), 0))] * n_exp
                dpred[j] = d
                return objs[j].profiled_columns(dpred)

            with ThreadPoolExecutor(max(1, threads)) as lib_pool:
                cols = list(lib_pool.map(one, range(n_exp)))
            for i, t in enumerate(missing):
                cache[(t.param, wavelength if t.periodic else 0.0)] = np.concatenate([c[:, i] for c in cols])
        sizes = np.cumsum([objs[j].samples[j] for j in range(n_exp)])[:-1]
        return np.split(np.stack([cache[k] for k in key], axis=1), sizes)

    force.library_view = library_view
    return force


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


#: step [N] of the forward differences that replace a knot's derivative which blew up
FD_FORCE_STEP = 1e-4
#: step [fit units] of the forward differences that replace the calibrated parameters'
#: derivatives which blew up (the fits' own step, fitting.Objective.jacobian)
FD_PARAM_STEP = 1e-3


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
    (the same test as the fits' :func:`~idm_rs.diagnosis.fitting.usable_derivative`)."""
    from .fitting import BLOWN_UP

    S = out["sensitivities"]  # samples x knots [m/N]
    pred = out["reading"]
    limit = BLOWN_UP * (float(np.ptp(pred)) + 1e-6)
    bad = [k for k in range(S.shape[1]) if not np.all(np.isfinite(S[:, k])) or np.max(np.abs(S[:, k])) > limit]
    for k in bad:
        v = values.copy()
        v[k] += FD_FORCE_STEP
        S[:, k] = (reading(v) - pred) / FD_FORCE_STEP
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
    _require_finite("the inferred force's normal equations", **{"J'J": G, "J'r": g})
    bb2 = sum(float(x @ x) for x in b)
    n = sum(x.size for x in b)
    scale = float(np.trace(G[:kt, :kt])) / max(float(np.trace(P)), 1e-300)
    best: Optional[tuple[float, float, NDArray[np.float64], float, float]] = None
    for rel in SMOOTHING_GRID:
        K = G + rel * scale * P
        try:
            sol = np.linalg.solve(K, np.column_stack([g, G]))
        except np.linalg.LinAlgError:
            sol = _lstsq(K, np.column_stack([g, G]), "the inferred force's normal equations", None)[0]
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
        x = _lstsq(G + best[1] * scale * P + damp, g + damp @ x0, "the inferred force's damped step", None)[0]
    cs = np.split(x[:kt], np.cumsum(sizes)[:-1])
    return list(cs), x[kt:], best[1], best[3], best[4]


# ---------------------------------------------------------------------------------------------
# Step 2: the form
# ---------------------------------------------------------------------------------------------

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
    if force.library_view is not None:
        X = force.library_view(terms, wavelength)
    else:
        X = [_knot_view(force, j, terms, wavelength) for j in range(len(force.jacobians))]
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


def _knot_view(force: InferredForce, j: int, terms: Sequence[Term], wavelength: float) -> NDArray[np.float64]:
    """The library's effect on experiment j's readings through the force's own derivatives:
    each function projected on the knots (the force's resolution), then pushed through
    `jacobians` (for a force made without the engine, or an experiment whose library
    derivatives could not be taken)."""
    A = force.jacobians[j]
    theta = library_columns(force.trajectories[j], terms, wavelength)[: A.shape[0]]
    return A @ force.on_knots(j, theta)


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
    _require_finite("the library's effect on the readings", library=Xa, force=np.concatenate(y))
    norms = np.sqrt(np.sum(Xa * Xa, axis=0))
    norms[norms == 0] = 1.0
    ya = np.concatenate(y)
    total = float(ya @ ya) - (ya.size if noisy else 0.0)
    errs: list[float] = [1.0]
    supports: list[NDArray[np.int64]] = [np.zeros(0, dtype=np.int64)]
    if total <= 0.0:
        return errs, supports
    m = len(X)
    for k in range(1, max_terms + 1):
        support = np.flatnonzero(_omp(Xa / norms, ya, k))
        if support.size < k and k > 1:
            break  # the library has no more independent directions
        sse = 0.0
        for hold in range(m):
            rest = [i for i in range(m) if i != hold]
            c = _lstsq(np.concatenate([X[i][:, support] for i in rest]), np.concatenate([y[i] for i in rest]),
                       "the form's cross-validation")[0]
            r = y[hold] - X[hold][:, support] @ c
            sse += float(r @ r) - (r.size if noisy else 0.0)
        errs.append(sse / total)
        supports.append(support)
    return errs, supports


def _omp(X: NDArray[np.float64], y: NDArray[np.float64], k: int) -> NDArray[np.float64]:
    """Orthogonal matching pursuit with at most `k` terms (scikit-learn); a library whose
    columns are linearly dependent (V and x1 - x2 follow each other) simply stops early."""
    import warnings

    from sklearn.linear_model import OrthogonalMatchingPursuit

    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        omp = OrthogonalMatchingPursuit(n_nonzero_coefs=min(k, X.shape[1]), fit_intercept=False).fit(X, y)
    return np.asarray(omp.coef_)


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

    def evaluate(terms: list[Term], wavelength: float):
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
        coef, rank = _lstsq(np.concatenate(X)[:, support], np.concatenate(y), "the form's coefficients")
        if rank < support.size:
            notes.append(f"the {support.size} terms chosen are linearly dependent on these experiments (rank "
                         f"{rank}): their coefficients are not determined one by one")
        for i, c in zip(support, coef):
            chosen.append(best_terms[i])
            coefs[best_terms[i].param] = float(c)
    wl = best_wl if any(t.periodic for t in chosen) else 0.0
    source = ("residual (direct)" if force.target is not None
              else "inferred force, calibration projected out" if project else "inferred force")
    return FoundForm(force.body, chosen, coefs, wl, float(errs[k]), [float(e) for e in errs], tried, notes, source)


# ---------------------------------------------------------------------------------------------
# Step 3: the term, modelled and refitted
# ---------------------------------------------------------------------------------------------

@dataclass
class Discovery:
    """What discovery found, with the evidence; `discovered` is the verdict's test."""

    discovered: bool
    reason: str
    body: str
    form: Optional[FoundForm]
    forces: dict[str, InferredForce]  #: per body tried
    refit: Optional[FitResult] = None
    #: the refitted library coefficients and their 1-sigma, engine parameter -> (value, std)
    values: dict[str, tuple[float, Optional[float]]] = field(default_factory=dict)
    delta_bic: float = math.nan
    rms_before: float = math.nan  #: the calibrated null's residual RMS [m]
    rms_after: float = math.nan
    heldout_rms_before: float = math.nan
    heldout_rms_after: float = math.nan
    heldout_experiment: str = ""
    description: str = ""  #: the term in words
    equation: str = ""  #: the term in symbols
    seconds: float = 0.0
    #: numerical failures that stopped a step (named, never a verdict)
    failures: list[str] = field(default_factory=list)
    #: the refitted forms that did not stand (each with its evidence), in the order tried
    tried: list["Discovery"] = field(default_factory=list)
    #: the refit's free parameters (the calibrated subset and the library's), centred on its optimum
    free: list[FreeParam] = field(default_factory=list, repr=False)

    def to_dict(self) -> dict[str, Any]:
        return {
            "discovered": self.discovered, "reason": self.reason, "body": self.body,
            "terms": [t.symbol for t in self.form.terms] if self.form else [],
            "variables": self.form.variables if self.form else [],
            "wavelength_m": self.form.wavelength if self.form else 0.0,
            "cv_error": self.form.cv_error if self.form else math.nan,
            "form_source": self.form.source if self.form else "",
            "values": {k: list(v) for k, v in self.values.items()},
            "delta_bic": self.delta_bic, "rms_before": self.rms_before, "rms_after": self.rms_after,
            "heldout_rms_before": self.heldout_rms_before, "heldout_rms_after": self.heldout_rms_after,
            "heldout_experiment": self.heldout_experiment, "description": self.description,
            "equation": self.equation, "seconds": self.seconds, "failures": self.failures,
            "notes": self.form.notes if self.form else [],
            "inferred_force": {b: {"chi2_before": f.chi2_before, "chi2_after": f.chi2_after, "dof": f.dof,
                                   "smoothing": f.smoothing} for b, f in self.forces.items()},
        }


#: each periodic term's partner in quadrature (the same kind of force a quarter period on)
QUADRATURE = {"lib_sin": "lib_cos", "lib_cos": "lib_sin", "lib_ff_sin": "lib_ff_cos", "lib_ff_cos": "lib_ff_sin"}


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


def _free_library(form: FoundForm) -> list[FreeParam]:
    """The found coefficients as free parameters (and the wavelength when a periodic term was
    found), started at the regression's values; a quadrature partner started at zero ranges
    over its partner's magnitude."""
    free = []
    for t in form.terms:
        v = form.coefficients[t.param]
        partner = QUADRATURE.get(t.param)
        if v == 0.0 and partner is not None and form.coefficients.get(partner):
            s = abs(form.coefficients[partner]) / 20.0
        else:
            s = max(abs(v), 1e-30)
        free.append(FreeParam(t.param, v, v - 20.0 * s, v + 20.0 * s, 0.1 * s, set_effect(t.param), unit=t.unit))
    if form.wavelength > 0:
        wl = form.wavelength
        free.append(FreeParam("lib_wavelength", wl, wl / 1.6, wl * 1.6, 0.02, set_effect("lib_wavelength"), log=True,
                              unit="m"))
    return free


def _equation(form: FoundForm, values: dict[str, float]) -> str:
    lhs = "m1 x1'' +=" if form.body == "main" else "m2 x2'' +="
    parts = []
    for t in form.terms:
        sym = t.symbol.replace("lambda", f"{values.get('lib_wavelength', form.wavelength) * 1e6:.3g} um")
        unit = "" if t.unit == "1" else f" {t.unit}"
        parts.append(f"{values[t.param]:+.4g}{unit} · {sym}")
    return f"{lhs} " + " ".join(parts)


def describe(form: FoundForm, values: dict[str, float], force: InferredForce) -> str:
    """The found term in words, with its size along the recorded motion."""
    wl = values.get("lib_wavelength", form.wavelength)
    where = "on the main body" if form.body == "main" else "on the weight"
    trs = force.trajectories
    ff = np.concatenate([np.abs(t.ff) for t in trs]) if trs else np.zeros(1)
    ff_level = float(np.percentile(ff, 90)) if ff.size else 0.0
    words = []
    names = {t.param for t in form.terms}
    if names & {"lib_ff_sin", "lib_ff_cos"}:
        amp = math.hypot(values.get("lib_ff_sin", 0.0), values.get("lib_ff_cos", 0.0))
        words.append(f"friction varies with position: about ±{100 * amp:.2g} % with a period of {wl * 1e6:.3g} µm")
    if names & {"lib_sin", "lib_cos"}:
        amp = math.hypot(values.get("lib_sin", 0.0), values.get("lib_cos", 0.0))
        words.append(f"a force periodic in position {where}: ±{amp * 1e3:.3g} mN with a period of {wl * 1e6:.3g} µm")
    if "lib_vv" in names:
        v = float(np.percentile(np.concatenate([np.abs(t.v1) for t in trs]), 99)) if trs else 0.0
        words.append(f"quadratic drag {where}: F = {values['lib_vv']:.3g} N s²/m² · v1|v1| "
                     f"({abs(values['lib_vv']) * v * v * 1e3:.3g} mN at {v * 1e3:.3g} mm/s)")
    if "lib_x1cube" in names:
        x = float(np.max(np.concatenate([np.abs(t.x1) for t in trs]))) if trs else 0.0
        kind = "stiffening spring to ground" if values["lib_x1cube"] < 0 else "softening (negative) cubic force"
        words.append(f"a cubic {kind} {where}: F = {values['lib_x1cube']:.3g} N/m³ · x1³ "
                     f"({abs(values['lib_x1cube']) * x**3 * 1e3:.3g} mN at {x * 1e6:.3g} µm)")
    if "lib_x1sq" in names:
        words.append(f"a force quadratic in position {where} ({values['lib_x1sq']:.3g} N/m² · x1²)")
    if "lib_x1" in names:
        words.append(f"a linear spring to ground {where} (k = {-values['lib_x1']:.3g} N/m)")
    if "lib_ff" in names:
        words.append(f"friction {100 * values['lib_ff']:+.2g} % off its calibrated level")
    rest = [t for t in form.terms if t.param not in {"lib_ff_sin", "lib_ff_cos", "lib_sin", "lib_cos", "lib_vv",
                                                      "lib_x1cube", "lib_x1sq", "lib_x1", "lib_ff"}]
    for t in rest:
        words.append(f"a force {values[t.param]:+.3g} {t.unit} · {t.symbol} {where}")
    if ff_level > 0 and not words:
        words.append("no term")
    return "; ".join(words)


def _refit(objective: Objective, spec: ModelSpec, calibrated_free: Sequence[FreeParam], form: FoundForm,
           progress: Optional[Callable[..., Any]]) -> tuple[FitResult, list[FreeParam]]:
    """The whole model refitted with the form's coefficients (and wavelength) free."""
    lib = _free_library(form)
    effects = dict(spec.effects)
    base = ModelSpec(spec.structure, dict(spec.params), effects)
    if form.wavelength > 0:
        effects["lib_wavelength"] = form.wavelength
    r = fit(objective, base, list(calibrated_free) + lib, max_nfev=REFIT_NFEV, progress=progress)
    return r, lib


def _refit_from(objective: Objective, spec: ModelSpec, starts: Sequence[Sequence[FreeParam]], form: FoundForm,
                progress: Optional[Callable[..., Any]]) -> tuple[FitResult, list[FreeParam], Sequence[FreeParam]]:
    """:func:`_refit` from each start of the calibrated parameters in turn, until one leaves
    noise (RMS within NOISE_RATIO_OK of sigma); the lowest chi^2, its library parameters and
    its start. The calibration's optimum mimics the missing term and the force's joint fit
    bends the parameters toward what a smooth force cannot do: either may leave the refit
    short of its basin in the evaluations it has."""
    best: Optional[tuple[FitResult, list[FreeParam], Sequence[FreeParam]]] = None
    for start in starts:
        r, lib = _refit(objective, spec, start, form, progress)
        if best is None or r.chi2 < best[0].chi2:
            best = (r, lib, start)
        if r.rms <= NOISE_RATIO_OK * objective.sigma:
            break
    assert best is not None
    return best


def _pruned(objective: Objective, spec: ModelSpec, calibrated_free: Sequence[FreeParam], form: FoundForm,
            r: FitResult, lib: list[FreeParam], progress: Optional[Callable[..., Any]]
            ) -> tuple[FoundForm, FitResult, list[FreeParam]]:
    """The form without its terms the refit does not support (|value| < PRUNE_Z sigma), when
    that lowers BIC: the regression picks terms greedily, and a second term may only mop up what
    the first left on the way."""
    def z(t: Term) -> float:
        sd = r.std.get(t.param)
        return abs(r.values[t.param]) / sd if sd else math.inf

    weak = [t for t in form.terms if z(t) <= PRUNE_Z]
    if len(weak) == len(form.terms):
        weak.remove(max(weak, key=z))  # all weak (correlated with each other): keep the clearest
    if not weak:
        return form, r, lib
    keep = [t for t in form.terms if t not in weak]
    coefs = {t.param: r.values[t.param] for t in keep}
    periodic = any(t.periodic for t in keep)
    wl = r.values.get("lib_wavelength", form.wavelength) if periodic else 0.0
    smaller = replace(form, terms=keep, coefficients=coefs, wavelength=wl)
    free = [f.at(r.values[f.name]) for f in calibrated_free]
    r2, lib2 = _refit(objective, spec, free, smaller, progress)
    ln_n = math.log(objective.n)
    # each term claimed must pay for itself as a catalogue effect does: by BIC_THRESHOLD
    if r2.chi2 + len(lib2) * ln_n < r.chi2 + len(lib) * ln_n + BIC_THRESHOLD:
        return smaller, r2, lib2
    return form, r, lib


def discover(rec: Recording, spec: ModelSpec, calibrated_free: Sequence[FreeParam], objective: Objective,
             heldout: Any, heldout_rms_null: float, *, bodies: Sequence[str] = ("main", "weight"),
             nominal: Optional[ModelSpec] = None, progress: Optional[Callable[..., Any]] = None) -> Discovery:
    """Discovery (module docstring) from the calibrated model `spec` with its calibrated subset
    `calibrated_free` (centred on the calibration's optimum) on `objective` (the diagnosis's
    segmented objective); `heldout` the diagnosis's held-out predictor (``rms(spec, free)``)
    and `heldout_rms_null` the null's held-out RMS [m]; `nominal` the recording's nominal
    model (a start of the refits). A force is inferred on each of `bodies`;
    the form found for each is refitted (in the order of how much of the residual each force
    explains; once a standing form leaves noise the others are not tried), and of those that
    stand the one with the lowest BIC is the answer (a force on the wrong body may explain the
    residual as well, and its form stand, while leaving more of it)."""
    import time

    t0 = time.perf_counter()
    sigma = objective.sigma
    forces: dict[str, InferredForce] = {}
    failures: list[str] = []
    for body in bodies:
        try:
            forces[body] = infer_force(rec, spec, sigma, body, simulator=objective.sim, nuisance=calibrated_free,
                                       progress=progress)
        except NumericalFailure as e:
            failures.append(f"the force on the {body}: {e}")
    null_chi2 = float(sum(np.sum(r * r) for r in objective.profiled(objective.predict([spec])[0])[0])) / sigma**2
    rms_null = math.sqrt(null_chi2 * sigma**2 / objective.n)
    order = sorted(forces, key=lambda b: -forces[b].gain)
    out = Discovery(False, "", order[0] if order else bodies[0], None, forces, rms_before=rms_null,
                    heldout_rms_before=heldout_rms_null,
                    heldout_experiment=rec.experiments[heldout.index].name if heldout is not None else "")
    out.failures = failures
    reasons: list[str] = []
    standing: list[Discovery] = []
    tried: list[Discovery] = []
    for body in order:
        force = forces[body]
        done = False
        refitted: set[frozenset[str]] = set()  # the forms refitted for this body (a phase may find one again)
        for phase in ("inferred", "direct"):
            # where the form is looked for: the inferred force's effect (plain, and in the complement
            # of the calibrated parameters); then, unless a form from it stood, the calibrated
            # residual itself by the library's exact sensitivities (direct: no knots between the
            # force and the library; it costs a second library scan, so it is taken only when needed)
            views: list[tuple[InferredForce, bool]] = []
            if phase == "inferred":
                if force.gain > BIC_THRESHOLD:
                    views += [(force, False)] + ([(force, True)] if force.nuisance else [])
                else:
                    reasons.append(f"no force on the {body} explains the residual (it lowers chi² by "
                                   f"{force.chi2_before - force.chi2_after:.0f} with {force.dof:.1f} effective "
                                   f"parameters)")
            else:
                try:
                    views.append((direct_force(rec, spec, sigma, body, simulator=objective.sim,
                                               nuisance=calibrated_free, progress=progress), bool(calibrated_free)))
                except NumericalFailure as e:
                    failures.append(f"the direct view of the {body}: {e}")
            forms: list[FoundForm] = []
            for view, project in views:
                try:
                    f_ = find_terms(view, project=project)
                except NumericalFailure as e:
                    kind = "direct" if view.target is not None else "inferred"
                    failures.append(f"the form on the {body} ({kind}): {e}")
                    continue
                if all({t.param for t in f_.terms} != {t.param for t in g.terms} for g in forms):
                    forms.append(f_)
            if not forms:
                continue
            found_any = [f_ for f_ in forms if f_.terms]
            form = found_any[0] if found_any else forms[0]
            if not form.terms:
                best_cv = min(min(f_.cv_by_size) for f_ in forms)
                lead = (f"a force on the {body} explains the residual (chi² {force.chi2_before:.0f} → "
                        f"{force.chi2_after:.0f}), but " if force.gain > BIC_THRESHOLD else "")
                reasons.append(f"{lead}no library term reproduces the {body}'s missing force across experiments "
                               f"({'inferred' if phase == 'inferred' else 'read directly off the residual'}: "
                               f"cross-validated error {best_cv:.2f} of what is to be explained, at best)")
                if out.form is None:
                    out.body, out.form = body, form
                continue
            # the fewest parameters first: once a form leaves noise, a larger one can at best tie
            # (a periodic form in x1 whose period is the step length mimics any function of the
            # drive's phase: on the drag device four periodic terms at 4.2 um reached 1.09 x noise,
            # v1|v1| alone 1.00)
            found_any.sort(key=lambda f_: len(f_.terms) + (f_.wavelength > 0))
            for form in found_any:
                key = frozenset(t.param for t in form.terms)
                if key in refitted:
                    continue
                refitted.add(key)
                form = with_quadrature(form)
                # the refit starts at the calibration's optimum, then (while a start leaves more
                # than noise) at the nominal values (with the missing term found, the calibration's
                # mimicry of it is no longer needed: on the drag device the calibration had moved
                # friction and damping to mimic the drag, and the refit from there stopped at
                # short of noise) and where the force's own fit left the calibrated parameters
                starts = [list(calibrated_free)]
                if nominal is not None:
                    starts.append([f.at(float(nominal.params.get(f.name) or f.x0)) for f in calibrated_free])
                if force.parameters:
                    starts.append([f.at(force.parameters.get(f.name, f.x0)) for f in calibrated_free])
                r, lib, start = _refit_from(objective, spec, starts, form, progress)
                for _ in range(PRUNE_ROUNDS):
                    smaller, r, lib = _pruned(objective, spec, start, form, r, lib, progress)
                    if smaller is form:
                        break
                    form = smaller
                trial = Discovery(False, "", body, form, forces, refit=r, rms_before=rms_null,
                                  heldout_rms_before=heldout_rms_null, heldout_experiment=out.heldout_experiment)
                trial.delta_bic = null_chi2 - r.chi2 - len(lib) * math.log(objective.n)
                trial.free = [f.at(r.values[f.name]) for f in list(start) + lib]
                trial.rms_after = r.rms
                vals = {f.name: r.values[f.name] for f in lib}
                trial.values = {n: (v, r.std.get(n)) for n, v in vals.items()}
                if heldout is not None:
                    trial.heldout_rms_after = heldout.rms(r.spec, [f.at(r.values[f.name]) for f in list(start) + lib])
                trial.equation = _equation(form, vals)
                trial.description = describe(form, vals, force)
                improves = not (math.isfinite(trial.heldout_rms_after) and math.isfinite(heldout_rms_null)
                                and trial.heldout_rms_after >= heldout_rms_null)
                # "discovered" means the residual is explained, not merely lowered: the refit leaves
                # noise and so does the held-out experiment's prediction (a floor vibration, which no
                # library term represents, was "explained" by sgn v1 and a periodic term at 2.16 x
                # noise, held out 3.2 x, before this rule)
                explains = (trial.rms_after <= NOISE_RATIO_OK * sigma
                            and not (math.isfinite(trial.heldout_rms_after)
                                     and trial.heldout_rms_after > NOISE_RATIO_OK * sigma))
                trial.discovered = trial.delta_bic >= BIC_THRESHOLD and improves and explains
                terms = ", ".join(t.symbol for t in form.terms)
                where = "main body" if body == "main" else "weight"
                if trial.discovered:
                    trial.reason = (f"a force on the {where} of the form {terms} ({trial.description}) improves "
                                    f"BIC by {trial.delta_bic:.0f} over the calibrated model (RMS "
                                    f"{rms_null / sigma:.2f} → {trial.rms_after / sigma:.2f} x noise) and predicts "
                                    f"the held-out experiment better "
                                    f"({heldout_rms_null * 1e9:.2f} → {trial.heldout_rms_after * 1e9:.2f} nm)")
                    standing.append(trial)
                    if trial.rms_after <= NOISE_RATIO_OK * sigma:
                        done = True  # it leaves noise: another form could at best tie
                        break
                    continue
                if trial.delta_bic < BIC_THRESHOLD:
                    why = f"ΔBIC {trial.delta_bic:.0f} < {BIC_THRESHOLD:g}"
                elif not improves:
                    why = (f"the held-out prediction does not improve ({heldout_rms_null * 1e9:.2f} → "
                           f"{trial.heldout_rms_after * 1e9:.2f} nm)")
                else:
                    why = (f"it improves BIC by {trial.delta_bic:.0f} but does not explain the residual: RMS "
                           f"{rms_null / sigma:.2f} → {trial.rms_after / sigma:.2f} x noise, held out "
                           f"{heldout_rms_null / sigma:.2f} → {trial.heldout_rms_after / sigma:.2f} x noise "
                           f"(both must reach {NOISE_RATIO_OK:g})")
                reasons.append(f"the form found on the {where} ({terms}) does not stand: {why}")
                trial.reason = why
                tried.append(trial)
                if out.refit is None:
                    out = trial
            if done:
                break
        if done:
            break
    if standing:
        best = max(standing, key=lambda x: x.delta_bic)
        others = [x for x in standing if x is not best]
        if others:
            best.reason += "; " + "; ".join(  # every standing trial has its form (the `else ()` never runs)
                f"the form on the {'main body' if x.body == 'main' else 'weight'} "
                f"({', '.join(t.symbol for t in (x.form.terms if x.form is not None else ()))}) also stands "
                f"but gains less (ΔBIC {x.delta_bic:.0f})"
                for x in others)
        best.seconds = time.perf_counter() - t0
        return best
    if failures:
        reasons.append("a numerical failure stopped part of discovery (no verdict on the physics): "
                       + "; ".join(failures))
    out.failures = failures
    out.reason = "; ".join(reasons)
    out.tried = [x for x in tried if x is not out]
    out.seconds = time.perf_counter() - t0
    return out
