"""Screening the catalogue at the null optimum: a Lagrange-multiplier (score) test per effect.

At the calibrated null model, the exact sensitivity of the readings to each effect's parameters
at (next to) "no effect" — projected off the null's own Jacobian, so an effect is credited only
with what the nominal parameters cannot do — gives the chi^2 drop one linearised step would
make. One sensitivity run per effect, no fit. The angles between the projected columns say
which effects the data cannot tell apart to first order (near-degenerate pairs)."""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any, Callable, Optional, Sequence, cast

import numpy as np
from numpy.typing import NDArray

from .case_model import ModelSpec
from .catalogue import Effect
from .fitting import FitResult, FreeParam, Objective
from .thresholds import DEGENERATE_COS


@dataclass(frozen=True)
class Screened:
    """One effect screened at the null optimum."""

    effect: Effect
    start: tuple[float, ...]  #: the effect's parameters where its columns were taken (the probe)
    delta_chi2: float  #: the score: chi^2 drop of one bounded linearised step, beyond the null's own
    estimate: list[float]  #: effect parameters after that step (within fit bounds)
    #: the step's direction in residual space, projected off the null's Jacobian (unit length)
    direction: Optional[NDArray[np.float64]] = field(default=None, repr=False, compare=False)
    #: the nominal subset after that step (fit units of the calibration's free parameters)
    nominal_step: Optional[NDArray[np.float64]] = field(default=None, repr=False, compare=False)

    @property
    def score(self) -> float:
        return self.delta_chi2


def probes(eff: Effect) -> list[tuple[float, ...]]:
    """Where an effect's columns are taken: every log-scaled parameter (a time constant, whose
    "no effect" is a limit the engine has no state for) at each of its starting values, every
    other at its "no effect" value — the score test's point — and, for a parameter with a kink
    there (a one-sided term like the Stribeck excess, whose derivative at "no effect" may be
    the wrong side's), at its starting values too."""
    grids = []
    for ep in eff.params:
        if ep.log:
            grids.append(tuple(ep.starts))
        elif ep.kink:
            grids.append(tuple(dict.fromkeys((ep.none,) + tuple(ep.starts))))
        else:
            grids.append((ep.none,))
    if not grids:
        return [()]
    return [tuple(c) for c in np.array(np.meshgrid(*grids, indexing="ij")).reshape(len(grids), -1).T]


def _project(Q: NDArray[np.float64], X: NDArray[np.float64]) -> NDArray[np.float64]:
    return cast("NDArray[np.float64]", X - Q @ (Q.T @ X))


def screen(obj: Objective, null: FitResult, null_at: list[FreeParam], effects: Sequence[Effect], sigma: float,
           progress: Optional[Callable[..., Any]] = None) -> list[Screened]:
    """The score of every effect at the null optimum `null` (its free parameters `null_at`,
    centred on it; its exact Jacobian `null.jac`)."""
    from scipy.optimize import lsq_linear

    r0 = np.concatenate(null.residuals) / sigma
    chi2_null = float(r0 @ r0)
    Jn = null.jac
    if Jn is None or Jn.shape[0] != r0.size:
        _, Jn, _ = obj.jacobian(null.spec, null_at, np.zeros(len(null_at)))
    Q, _ = np.linalg.qr(Jn)
    lo_n = np.array([f.u_bounds()[0] for f in null_at])
    hi_n = np.array([f.u_bounds()[1] for f in null_at])
    # what a further step of the nominal subset alone would gain (a local fit stops near, not
    # at, its optimum): each effect is credited only with what it adds beyond that
    du_n = lsq_linear(Jn, -r0, bounds=(np.minimum(lo_n, -1e-12), np.maximum(hi_n, 1e-12))).x
    chi2_null = float(np.sum((r0 + Jn @ du_n) ** 2))
    out: list[Screened] = []
    for eff in effects:
        base = ModelSpec(eff.structure(null.spec.structure), dict(null.spec.params), dict(null.spec.effects))
        best: Optional[Screened] = None
        for probe, free, r, G in _columns(obj, base, eff, progress):
            A = np.concatenate([Jn, G], axis=1)
            bounds = [(a, b) for a, b in zip(lo_n, hi_n)] + [f.u_bounds() for f in free]
            lo = np.minimum([b[0] for b in bounds], -1e-12)
            hi = np.maximum([b[1] for b in bounds], 1e-12)
            if not np.all(np.isfinite(A)) or not np.all(np.isfinite(r)):
                continue
            du = lsq_linear(A, -r, bounds=(lo, hi)).x
            chi2_lin = float(np.sum((r + A @ du) ** 2))
            score = chi2_null - chi2_lin
            step = _project(Q, G @ du[Jn.shape[1]:]) if free else _project(Q, r - r0)
            norm = float(np.linalg.norm(step))
            est = [f.value(float(np.clip(d, *f.u_bounds()))) for f, d in zip(free, du[Jn.shape[1]:])]
            s = Screened(eff, probe, score, est, step / norm if norm > 0 else None, du[: Jn.shape[1]])
            if best is None or s.delta_chi2 > best.delta_chi2:
                best = s
        if best is None:
            best = Screened(eff, probes(eff)[0], -math.inf, [ep.none for ep in eff.params])
        out.append(best)
    return out


def _columns(obj: Objective, base: ModelSpec, eff: Effect, progress: Optional[Callable[..., Any]]
             ) -> list[tuple[tuple[float, ...], list[FreeParam], NDArray[np.float64], NDArray[np.float64]]]:
    """(probe, its free parameters, residual vector, exact columns of the effect's parameters) at
    every probe of `eff`: one batch call with sensitivities for all of them."""
    from .fitting import apply, difference_columns, engine_chain, usable_derivative

    frees = [[ep.free(v) for ep, v in zip(eff.params, probe)] for probe in probes(eff)]
    if not eff.params:  # a structure change, no parameter: one Gauss-Newton step of the nominal subset
        r = obj.vector(obj.predict([base])[0])
        return [((), [], r, np.zeros((r.size, 0)))]
    specs = [apply(base, free, np.zeros(len(free))) for free in frees]
    names, D = engine_chain(base, frees[0], np.zeros(len(frees[0])))
    preds, sens, _ = obj.sim.predict_with_sensitivities(specs, names, obj.cycles)
    if progress:
        progress(len(specs))
    out = []
    for probe, free, _spec, p, sn in zip(probes(eff), frees, specs, preds, sens):
        _, D = engine_chain(base, free, np.zeros(len(free)))
        dpred = [D.T @ x for x in sn]
        bad = [j for j, (d, x) in enumerate(zip(dpred, p)) if x.size and not usable_derivative(d, x)]
        if bad:  # derivatives not taken there: forward differences of those experiments
            _, cols = difference_columns(obj, base, free, np.zeros(len(free)), bad, preds=p)
            for j in bad:
                dpred[j] = cols[j]
        out.append((probe, free, obj.vector(p), obj.profiled_columns(dpred)))
    return out


def near_degenerate(screened: Sequence[Screened], cos: float = DEGENERATE_COS
                    ) -> list[tuple[str, str, float]]:
    """Pairs of effects whose projected step directions are within the angle `cos` (|cos| above
    it): (effect, effect, |cos|), most alike first."""
    pairs = []
    for i, a in enumerate(screened):
        for b in screened[i + 1:]:
            if a.direction is None or b.direction is None:
                continue
            c = abs(float(a.direction @ b.direction))
            if c >= cos:
                pairs.append((a.effect.id, b.effect.id, c))
    return sorted(pairs, key=lambda p: -p[2])
