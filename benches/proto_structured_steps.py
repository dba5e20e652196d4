"""Issue 54's prototype, the structured candidates: a Runge-Kutta-Nystrom pair for the mechanical
second-order part, an exponential (Lawson) Dormand-Prince that takes a linear part of the
oscillators exactly, and the higher-order explicit pairs the first table let DOP853 stand for
(Tsitouras 5(4), Verner 6(5)). Same right-hand side, points, ladder and 1 nm check as
``proto_fewer_steps.py`` (whose runner table these join).

- ``fine_rkn4`` / ``fine_rkn5``: Fine's (1987) pairs for y'' = f(t, y, y') (order 4(3), 5 stages;
  order 5(4), 7 stages, the last at the new point). Positions advance by the Nystrom weights; the
  velocities and every first-order state (the friction state, the piezo hysteresis) by the pair's
  velocity weights, which form a Runge-Kutta method of the same order. Which components are
  positions is read from the right-hand side (dy[i] = y[j]). A *special* Nystrom pair (fewer
  stages, f independent of y') does not apply: friction and Rayleigh damping depend on velocity.
- ``lawson5_rest`` / ``lawson5_lag`` / ``lawson5_each``: Dormand-Prince 5(4) in Lawson's
  integrating-factor form, y' = L y + N(t, y) with N = f - L y, every stage and weight carried by
  exp(tau h L) (exact for the linear part: the presliding and PE oscillators' ringing while L
  describes them). L is the Jacobian of the right-hand side at rest (``rest``), refreshed at the
  current state after a rejected step (``lag``), or at every step (``each``). exp(tau h L) is
  applied through L's eigenvectors (the stages kept in the eigenbasis: one product with the
  eigenvector matrix and one with its inverse per stage); a refresh costs a Jacobian and an
  eigendecomposition.

Work is counted in right-hand-side equivalents: evaluations (a Jacobian as 2, as an analytic one
would cost), plus the linear algebra by flops at the rate ``proto_fewer_steps.unit_costs``
measures (a complex n x n product with a vector 8 n^2 flops, an eigendecomposition 25 n^3).

    python benches/proto_structured_steps.py --models lps,dps --methods fine_rkn4,fine_rkn5,tsit5,vern6 \
        --json benches/results/proto_structured_explicit.json
    python benches/proto_structured_steps.py --models lps --methods lawson5_rest,lawson5_lag,lawson5_each \
        --json benches/results/proto_structured_lawson.json
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path
from typing import Any

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
import proto_fewer_steps as pfs

#: Fine (1987), RKN 4(3) for y'' = f(t, y, y'): nodes, position (h^2) and velocity (h) stage
#: coefficients, weights, and the differences of the embedded pair's weights
FINE4_C = [0.0, 2 / 9, 1 / 3, 3 / 4, 1.0]
FINE4_APOS = [[], [2 / 81], [1 / 36, 1 / 36], [9 / 128, 0.0, 27 / 128], [11 / 60, -3 / 20, 9 / 25, 8 / 75]]
FINE4_AVEL = [[], [2 / 9], [1 / 12, 1 / 4], [69 / 128, -243 / 128, 135 / 64], [-17 / 12, 27 / 4, -27 / 5, 16 / 15]]
FINE4_BPOS = [19 / 180, 0.0, 63 / 200, 16 / 225, 1 / 120]
FINE4_BVEL = [1 / 9, 0.0, 9 / 20, 16 / 45, 1 / 12]
FINE4_EPOS = [25 / 1116, 0.0, -63 / 1240, 64 / 1395, -13 / 744]
FINE4_EVEL = [2 / 125, 0.0, -27 / 625, 32 / 625, -3 / 125]
#: Fine (1987), RKN 5(4): 7 stages, the last at the new point (first same as last)
FINE5_C = [0.0, 8 / 39, 4 / 13, 5 / 6, 43 / 47, 1.0, 1.0]
FINE5_APOS = [[], [32 / 1521], [4 / 169, 4 / 169], [175 / 5184, 0.0, 1625 / 5184],
              [-342497279 / 5618900760, 6827067 / 46824173, 35048741 / 102161832, -2201514 / 234120865],
              [-7079 / 52152, 767 / 2173, 14027 / 52152, 30 / 2173],
              [4817 / 51600, 0.0, 388869 / 1216880, 3276 / 23575, -1142053 / 22015140]]
FINE5_AVEL = [[], [8 / 39], [1 / 13, 3 / 13], [7385 / 6912, -9425 / 2304, 13325 / 3456],
              [223324757 / 91364240, -174255393 / 18272848, 382840094 / 46824173, -39627252 / 234120865],
              [108475 / 36464, -9633 / 848, 7624604 / 806183, 8100 / 49979, -4568212 / 19446707],
              [4817 / 51600, 0.0, 1685099 / 3650640, 19656 / 23575, -53676491 / 88060560, 53 / 240]]
FINE5_BPOS = [4817 / 51600, 0.0, 388869 / 1216880, 3276 / 23575, -1142053 / 22015140, 0.0, 0.0]
FINE5_BVEL = [4817 / 51600, 0.0, 1685099 / 3650640, 19656 / 23575, -53676491 / 88060560, 53 / 240, 0.0]
FINE5_EPOS = [8151 / 2633750, 0.0, -1377519 / 186334750, 586872 / 28879375, -36011118 / 2247378875, 0.0, 0.0]
FINE5_EVEL = [8151 / 2633750, 0.0, -5969249 / 559004250, 3521232 / 28879375, -846261273 / 4494757750,
              4187 / 36750, -1 / 25]
FINE = {"fine_rkn4": (FINE4_C, FINE4_APOS, FINE4_AVEL, FINE4_BPOS, FINE4_BVEL, FINE4_EPOS, FINE4_EVEL, 4),
        "fine_rkn5": (FINE5_C, FINE5_APOS, FINE5_AVEL, FINE5_BPOS, FINE5_BVEL, FINE5_EPOS, FINE5_EVEL, 5)}

#: Dormand-Prince 5(4): nodes, stage coefficients, 5th-order weights, 4th-order weights
DP_C = [0.0, 1 / 5, 3 / 10, 4 / 5, 8 / 9, 1.0, 1.0]
DP_A = [[], [1 / 5], [3 / 40, 9 / 40], [44 / 45, -56 / 15, 32 / 9],
        [19372 / 6561, -25360 / 2187, 64448 / 6561, -212 / 729],
        [9017 / 3168, -355 / 33, 46732 / 5247, 49 / 176, -5103 / 18656],
        [35 / 384, 0.0, 500 / 1113, 125 / 192, -2187 / 6784, 11 / 84]]
DP_B = [35 / 384, 0.0, 500 / 1113, 125 / 192, -2187 / 6784, 11 / 84, 0.0]
DP_BHAT = [5179 / 57600, 0.0, 7571 / 16695, 393 / 640, -92097 / 339200, 187 / 2100, 1 / 40]

#: Tsitouras 5(4) (2011): 7 stages, the last at the new point (its weights the last row), and
#: the differences of the embedded weights
TSIT5_C = [0.0, 0.161, 0.327, 0.9, 0.9800255409045097, 1.0, 1.0]
TSIT5_A = [[], [0.161], [-0.008480655492356989, 0.335480655492357],
           [2.8971530571054935, -6.359448489975075, 4.3622954328695815],
           [5.325864828439257, -11.748883564062828, 7.4955393428898365, -0.09249506636175525],
           [5.86145544294642, -12.92096931784711, 8.159367898576159, -0.071584973281401, -0.028269050394068383],
           [0.09646076681806523, 0.01, 0.4798896504144996, 1.379008574103742, -3.290069515436081,
            2.324710524099774]]
TSIT5_E = [-0.00178001105222577714, -0.0008164344596567469, 0.007880878010261995, -0.1447110071732629,
           0.5823571654525552, -0.45808210592918697, 0.015151515151515152]
#: Verner's "most efficient" 6(5) (2010): 9 stages, the last at the new point
VERN6_C = [0.0, 0.06, 0.09593333333333333, 0.1439, 0.4973, 0.9725, 0.9995, 1.0, 1.0]
VERN6_A = [[], [0.06], [0.019239962962962962, 0.07669337037037037], [0.035975, 0.0, 0.107925],
           [1.3186834152331484, 0.0, -5.042058063628562, 4.220674648395414],
           [-41.87259166432751, 0.0, 159.43256216313748, -122.11921356501004, 5.531743066200053],
           [-54.430156935316504, 0.0, 207.06725136501848, -158.61081378459, 6.991816585950242,
            -0.01859723106220323],
           [-54.66374178728198, 0.0, 207.95280625538936, -159.2889574744995, 7.018743740796944,
            -0.018338785905045722, -0.0005119484997882099],
           [0.03438957868357036, 0.0, 0.0, 0.25826245556335037, 0.4209371189673537, 4.40539646966931,
            -176.48311902429865, 172.36413340141507]]
VERN6_E = [0.008623404282200854, 0.0, 0.0, -0.019434029953152708, 0.028450072588037983, -2.1097110610652914,
           103.45854289996397, -101.39980461914912, 0.03333333333333333]
EXPLICIT = {"tsit5": (TSIT5_C, TSIT5_A, TSIT5_E, 5), "vern6": (VERN6_C, VERN6_A, VERN6_E, 6)}

#: flops per ns of dense products on this machine (proto_fewer_steps.unit_costs: ~4)
FLOPS_PER_NS = 4.0


def velocity_of(rhs: pfs.Rhs) -> dict[int, int]:
    """{position component: its velocity component}, read from the right-hand side: dy[i] equals
    y[j] at two random states."""
    rng = np.random.default_rng(0)
    ys = [rng.normal(size=rhs.dim) * 1e-6 for _ in range(2)]
    dys = [rhs(1e-4, 10.0, 1e3, y) for y in ys]
    out = {}
    for i in range(rhs.dim):
        for j in range(rhs.dim):
            if j != i and all(dy[i] == y[j] for y, dy in zip(ys, dys)):
                out[i] = j
    return out


def _norm(err: np.ndarray, y0: np.ndarray, y1: np.ndarray, tol: float, sc: np.ndarray) -> float:
    counted = np.isfinite(sc)
    tolv = tol * sc[counted] + tol * np.maximum(np.abs(y0[counted]), np.abs(y1[counted]))
    return float(np.sqrt(np.mean((err[counted] / tolv) ** 2)))


def run_fine(rhs: pfs.Rhs, segs: list, tol: float, scales: np.ndarray, name: str) -> dict[str, Any]:
    """Fine's RKN pair `name` on the mixed system (positions by Nystrom weights, the rest by the
    velocity weights)."""
    c, apos, avel, bpos, bvel, epos, evel, order = FINE[name]
    vel = velocity_of(rhs)
    pos = np.array(sorted(vel))
    pv = np.array([vel[i] for i in pos])
    first = np.array([i for i in range(rhs.dim) if i not in vel])  # velocities and first-order states
    sc = np.where(np.isfinite(scales), scales, np.inf)
    y = np.zeros(rhs.dim)
    steps = attempts = 0
    rhs.calls = 0
    h = 1e-8
    fsal = c[-1] == 1.0 and c[-2] == 1.0
    for ta, tb, va, s in segs:
        t = ta
        k0 = None
        while t < tb * (1 - 1e-15):
            h = min(h, tb - t)
            while True:
                attempts += 1
                ks = [k0 if k0 is not None else rhs(t, va + s * (t - ta), s, y)]
                for i in range(1, len(c)):
                    yi = y.copy()
                    yi[pos] = y[pos] + h * c[i] * y[pv] + h * h * sum(a * k[pv] for a, k in zip(apos[i], ks))
                    yi[first] = y[first] + h * sum(a * k[first] for a, k in zip(avel[i], ks))
                    ti = t + c[i] * h
                    ks.append(rhs(ti, va + s * (ti - ta), s, yi))
                y1 = y.copy()
                y1[pos] = y[pos] + h * y[pv] + h * h * sum(b * k[pv] for b, k in zip(bpos, ks))
                y1[first] = y[first] + h * sum(b * k[first] for b, k in zip(bvel, ks))
                err = np.zeros(rhs.dim)
                err[pos] = h * h * sum(e * k[pv] for e, k in zip(epos, ks))
                err[first] = h * sum(e * k[first] for e, k in zip(evel, ks))
                e = _norm(err, y, y1, tol, sc)
                if e <= 1.0 and np.all(np.isfinite(y1)):
                    y, t = y1, t + h
                    k0 = ks[-1] if fsal else None
                    steps += 1
                    h *= min(5.0, 0.9 * e ** (-1 / order)) if e > 0 else 5.0
                    break
                k0 = ks[0]
                h *= max(0.1, 0.9 * e ** (-1 / order)) if np.isfinite(e) else 0.1
                if h < 1e-15:
                    return dict(ok=False)
    return dict(ok=True, x1=float(y[0]), steps=steps, attempts=attempts, rhs=rhs.calls,
                rhs_analytic_jacobian=rhs.calls, positions=len(pos))


def run_explicit(rhs: pfs.Rhs, segs: list, tol: float, scales: np.ndarray, name: str) -> dict[str, Any]:
    """An explicit pair whose last stage is the new point (first same as last): Tsitouras 5(4),
    Verner 6(5)."""
    c, a, e_w, order = EXPLICIT[name]
    sc = np.where(np.isfinite(scales), scales, np.inf)
    y = np.zeros(rhs.dim)
    steps = attempts = 0
    rhs.calls = 0
    h = 1e-8
    for ta, tb, va, s in segs:
        t = ta
        k0 = rhs(t, va, s, y)
        while t < tb * (1 - 1e-15):
            h = min(h, tb - t)
            while True:
                attempts += 1
                ks = [k0]
                for i in range(1, len(c)):
                    yi = y + h * sum(aij * k for aij, k in zip(a[i], ks))
                    ti = t + c[i] * h
                    ks.append(rhs(ti, va + s * (ti - ta), s, yi))
                    if i == len(c) - 1:
                        y1 = yi
                err = h * sum(w * k for w, k in zip(e_w, ks))
                e = _norm(err, y, y1, tol, sc)
                if e <= 1.0 and np.all(np.isfinite(y1)):
                    y, t, k0 = y1, t + h, ks[-1]
                    steps += 1
                    h *= min(5.0, 0.9 * e ** (-1 / order)) if e > 0 else 5.0
                    break
                h *= max(0.1, 0.9 * e ** (-1 / order)) if np.isfinite(e) else 0.1
                if h < 1e-15:
                    return dict(ok=False)
    return dict(ok=True, x1=float(y[0]), steps=steps, attempts=attempts, rhs=rhs.calls,
                rhs_analytic_jacobian=rhs.calls)


class _Exp:
    """exp(tau h L) through L's eigenvectors: L = V diag(lam) V^-1."""

    def __init__(self, jac: np.ndarray) -> None:
        self.lam, self.v = np.linalg.eig(jac)
        self.vinv = np.linalg.inv(self.v)
        self.cond = float(np.linalg.cond(self.v))
        self.jac = jac


def run_lawson(rhs: pfs.Rhs, segs: list, tol: float, scales: np.ndarray, refresh: str) -> dict[str, Any]:
    """Lawson-Dormand-Prince 5(4) with L the Jacobian at rest (`refresh` 'rest'), refreshed at the
    current state after a rejection ('lag') or at every step ('each'). The stages live in L's
    eigenbasis (u = V^-1 y): exp(tau h L) is diagonal there."""
    n = rhs.dim
    sc = np.where(np.isfinite(scales), scales, np.inf)
    diag_sc = np.where(np.isfinite(sc), sc, 1e-6)
    y = np.zeros(n)
    steps = attempts = refreshes = matvecs = 0
    worst_cond = 1.0
    rhs.calls = 0

    def jacobian(t: float, va: float, s: float, ta: float, yy: np.ndarray) -> np.ndarray:
        f0 = rhs(t, va + s * (t - ta), s, yy)
        jac = np.empty((n, n))
        for j in range(n):
            dz = 1e-7 * max(abs(yy[j]), diag_sc[j])
            yp = yy.copy()
            yp[j] += dz
            jac[:, j] = (rhs(t, va + s * (t - ta), s, yp) - f0) / dz
        return jac

    h = 1e-8
    ex = None
    jac_calls = 0
    for ta, tb, va, s in segs:
        t = ta
        if ex is None:
            before = rhs.calls
            ex = _Exp(jacobian(t, va, s, ta, y))
            jac_calls += rhs.calls - before
            refreshes += 1
        rejected = False
        while t < tb * (1 - 1e-15):
            h = min(h, tb - t)
            if refresh == "each" or (refresh == "lag" and rejected):
                before = rhs.calls
                ex = _Exp(jacobian(t, va, s, ta, y))
                jac_calls += rhs.calls - before
                refreshes += 1
            worst_cond = max(worst_cond, ex.cond)
            u0 = ex.vinv @ y
            matvecs += 1
            while True:
                attempts += 1
                lam_h = ex.lam * h
                nu: list[np.ndarray] = []  # V^-1 N_j, the stages' nonlinear parts in the eigenbasis
                for i in range(7):
                    ui = np.exp(DP_C[i] * lam_h) * u0
                    for j, a in enumerate(DP_A[i]):
                        if a:
                            ui = ui + h * a * np.exp((DP_C[i] - DP_C[j]) * lam_h) * nu[j]
                    yi = (ex.v @ ui).real if i else y
                    ti = t + DP_C[i] * h
                    fi = rhs(ti, va + s * (ti - ta), s, yi)
                    nu.append(ex.vinv @ (fi - ex.jac @ yi))
                    matvecs += 3 if i else 2
                carried = [np.exp((1 - cj) * lam_h) * nj for cj, nj in zip(DP_C, nu)]
                u1 = np.exp(lam_h) * u0 + h * sum(b * x for b, x in zip(DP_B, carried))
                du = h * sum((b - bh) * x for b, bh, x in zip(DP_B, DP_BHAT, carried))
                y1, err = (ex.v @ u1).real, (ex.v @ du).real
                matvecs += 2
                e = _norm(err, y, y1, tol, sc)
                if e <= 1.0 and np.all(np.isfinite(y1)):
                    y, t = y1, t + h
                    steps += 1
                    rejected = False
                    h *= min(5.0, 0.9 * e ** (-1 / 5)) if e > 0 else 5.0
                    break
                rejected = True
                h *= max(0.1, 0.9 * e ** (-1 / 5)) if np.isfinite(e) else 0.1
                if h < 1e-15:
                    return dict(ok=False)
                if refresh == "lag":
                    break  # refresh L at this state before the retry
    # a complex matrix-vector product 8 n^2 flops; an eigendecomposition and inverse ~25 n^3
    return dict(ok=True, x1=float(y[0]), steps=steps, attempts=attempts, rhs=rhs.calls, refreshes=refreshes,
                matvecs=matvecs, eigenvector_cond=worst_cond,
                rhs_analytic_jacobian=rhs.calls - jac_calls + 2 * refreshes,
                linalg_flops=8 * n * n * matvecs + 25 * n ** 3 * refreshes)


RUNNERS = {
    "tsit5": lambda rhs, segs, tol, sc: run_explicit(rhs, segs, tol, sc, "tsit5"),
    "vern6": lambda rhs, segs, tol, sc: run_explicit(rhs, segs, tol, sc, "vern6"),
    "fine_rkn4": lambda rhs, segs, tol, sc: run_fine(rhs, segs, tol, sc, "fine_rkn4"),
    "fine_rkn5": lambda rhs, segs, tol, sc: run_fine(rhs, segs, tol, sc, "fine_rkn5"),
    "lawson5_rest": lambda rhs, segs, tol, sc: run_lawson(rhs, segs, tol, sc, "rest"),
    "lawson5_lag": lambda rhs, segs, tol, sc: run_lawson(rhs, segs, tol, sc, "lag"),
    "lawson5_each": lambda rhs, segs, tol, sc: run_lawson(rhs, segs, tol, sc, "each"),
}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--models", default="lps")
    ap.add_argument("--methods", default=",".join(RUNNERS))
    ap.add_argument("--points", default="", help="comma-separated name fragments (default: all)")
    ap.add_argument("--json", type=Path)
    a = ap.parse_args()
    pfs.RUNNERS.update(RUNNERS)
    rows: list[dict[str, Any]] = []
    for model in a.models.split(","):
        costs = pfs.unit_costs(model)
        for name, point in pfs.POINTS.items():
            if a.points and not any(f in name for f in a.points.split(",")):
                continue
            for r in pfs.measure(name, point, model, a.methods.split(",")):
                if "linalg_flops" in r:
                    r["rhs_equivalents_total"] = round(r["rhs_analytic_jacobian"]
                                                       + r["linalg_flops"] / FLOPS_PER_NS / costs["rhs_ns"])
                elif "rhs_analytic_jacobian" in r:
                    r["rhs_equivalents_total"] = r["rhs_analytic_jacobian"]
                rows.append(r)
            if a.json:
                a.json.write_text(json.dumps(rows, indent=1))


if __name__ == "__main__":
    main()
