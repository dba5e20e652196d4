"""Rao-score screening of the catalogue: the chi^2 drop each effect would give in one
linearised step about the calibrated model, from one batch of Jacobian columns. It catches
effects that grow over the drive cycles (a ground spring, drift, creep) and so hide in the
first-cycle fits."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Sequence

import numpy as np

from .case_model import ModelSpec
from .catalogue import Effect
from .fitting import FitResult, FreeParam, Objective, apply


@dataclass(frozen=True)
class Screened:
    """One effect screened about the calibrated model."""

    effect: Effect
    start: tuple[float, ...]  #: the multi-start value the step starts from (effect parameters)
    delta_chi2: float  #: chi^2 drop the linearised step gives beyond the nominal parameters' own
    estimate: list[float]  #: effect parameters at the linearised optimum (within fit bounds)


def screen(obj: Objective, cal: FitResult, cal_at: list[FreeParam], effects: Sequence[Effect],
           sigma: float) -> list[Screened]:
    """Rao-score screening: the chi^2 drop a Gauss-Newton step would give when each effect's
    parameters join the calibrated ones, from one batch of Jacobian columns. Multi-start values
    of nonlinear parameters are compared by their own chi^2 first."""
    from scipy.optimize import lsq_linear

    r0 = np.concatenate(cal.residuals) / sigma
    h = 1e-3
    specs: list[ModelSpec] = []
    # nominal columns
    for j in range(len(cal_at)):
        u = np.zeros(len(cal_at))
        u[j] = h
        specs.append(apply(cal.spec, cal_at, u))
    plan: list[dict[str, Any]] = []
    for eff in effects:
        base = ModelSpec(eff.structure(cal.spec.structure), dict(cal.spec.params), dict(cal.spec.effects))
        grids = [ep.starts for ep in eff.params]
        starts = [tuple(s) for s in np.array(np.meshgrid(*grids, indexing="ij")).reshape(len(grids), -1).T] if grids else [()]
        entry = {"effect": eff, "base": base, "starts": starts, "start_idx": len(specs)}
        for st in starts:  # the effect at each start
            free = [ep.free(v) for ep, v in zip(eff.params, st)]
            specs.append(apply(base, free, np.zeros(len(free))))
        plan.append(entry)
    preds = obj.predict(specs)
    Jn = np.stack([(obj.vector(preds[j]) - r0) / h for j in range(len(cal_at))], axis=1)
    # second pass: derivatives of the effect parameters at the best start
    specs2, plan2 = [], []
    for entry in plan:
        eff = entry["effect"]
        chis = [float(np.sum(obj.vector(preds[entry["start_idx"] + i]) ** 2)) for i in range(len(entry["starts"]))]
        best = int(np.argmin(chis))
        entry["start"] = entry["starts"][best]
        entry["r_start"] = obj.vector(preds[entry["start_idx"] + best])
        free = [ep.free(v) for ep, v in zip(eff.params, entry["start"])]
        entry["free"] = free
        idx = len(specs2)
        for j, f in enumerate(free):
            lo, hi = f.u_bounds()
            u = np.zeros(len(free))
            u[j] = h if h <= hi else -h
            specs2.append(apply(entry["base"], free, u))
        entry["cols"] = (idx, [(h if h <= f.u_bounds()[1] else -h) for f in free])
        plan2.append(entry)
    preds2 = obj.predict(specs2) if specs2 else []
    out: list[Screened] = []
    # baseline: what a further step in the nominal parameters alone would gain (the calibration
    # stops near, not at, its optimum); each effect is credited only with what it adds
    lo_n = np.array([f.u_bounds()[0] for f in cal_at])
    hi_n = np.array([f.u_bounds()[1] for f in cal_at])
    du_n = lsq_linear(Jn, -r0, bounds=(np.minimum(lo_n, -1e-12), np.maximum(hi_n, 1e-12))).x
    chi2_cal = float(np.sum((r0 + Jn @ du_n) ** 2))
    for entry in plan2:
        idx, steps = entry["cols"]
        rs = entry["r_start"]
        Je = [(obj.vector(preds2[idx + j]) - rs) / s for j, s in enumerate(steps)]
        A = np.concatenate([Jn, np.stack(Je, axis=1)], axis=1) if Je else Jn
        # bounded Gauss-Newton step from the start point: chi2 at the linearised optimum
        bounds = [f.u_bounds() for f in cal_at] + [f.u_bounds() for f in entry["free"]]
        lo = np.array([b[0] for b in bounds])
        hi = np.array([b[1] for b in bounds])
        du = lsq_linear(A, -rs, bounds=(np.minimum(lo, -1e-12), np.maximum(hi, 1e-12))).x
        chi2_lin = float(np.sum((rs + A @ du) ** 2))
        est = [f.value(float(np.clip(d, *f.u_bounds()))) for f, d in zip(entry["free"], du[Jn.shape[1]:])]
        out.append(Screened(entry["effect"], entry["start"], chi2_cal - chi2_lin, est))
    return out
