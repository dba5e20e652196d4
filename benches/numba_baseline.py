"""A careful numba implementation of the IDM model, the baseline that idm-rs's step cost is
measured against (``bench_step_cost.py``), and, run over many points with ``prange``
(:func:`sweep_x1`), the baseline of the sweep benchmark (``bench_sweep.py``).

It is written the way an experienced numba user would write it from ``MODEL.md``, sharing no
code with idm-rs: fixed-step classical RK4 over a flat state vector, all buffers
allocated once before the time loop, the structural matrices reduced with numpy to the dense
products M^-1 K, M^-1 C and the two columns of M^-1 that the forces load, and the common
parameter values special-cased where that avoids a ``pow`` (Stribeck exponent δ = 2, Leuven
exponent n = 1). ``fastmath`` stays off so that the result can be compared with idm-rs to
round-off (IEEE semantics, no reassociation). ``error_model="numpy"`` drops the Python-style
zero-division checks (S(v) > 0 always, so they could never fire but cost a branch per
division), and the right-hand side is inlined into the stepping loop at numba-IR level;
together the two take about a third off the step time here (measured on the paper case).

State layout, N nodes (node 0 = main body x1 at z = l, node N-1 = weight at z = 0):

    y = [q_0 .. q_{N-1},  v_0 .. v_{N-1},  g,  Fh,  h]
          nodal displ. [m]  velocities [m/s]  [m] [N] [m]

SI units throughout.
"""

from __future__ import annotations

from typing import Mapping

import numpy as np
from numba import njit, prange

# Indices into the packed constant vector handed to the kernel. A flat float64 array keeps
# the njit signatures short and lets one compiled kernel serve every parameter set.
KP, D33, AP_D33, BP, CP, FC, FS_MINUS_FC, INV_VS, DELTA, FRIC_N, A, B, C, SIGMA1, SIGMA2 = range(15)
N_CONST = 15


@njit(cache=True, fastmath=False, error_model="numpy", inline="always")
def _sign0(x):
    """sgn(x) with sgn(0) = 0 (needed so that Fh = 0 gives dg/dt = v exactly)."""
    if x > 0.0:
        return 1.0
    if x < 0.0:
        return -1.0
    return 0.0


@njit(cache=True, fastmath=False, error_model="numpy", inline="always")
def _rhs(y, volt, dvolt, nn, minv_k, minv_c, minv_main, minv_weight, prm, delta_is_two, n_is_one, dy):
    """dy/dt for state ``y`` at PE voltage ``volt`` [V] changing at ``dvolt`` [V/s].

    ``nn`` is the number of nodes; ``minv_*`` are the precomputed structural products
    (row-major N x N, and length-N columns); ``prm`` the packed constants.
    """
    ig = 2 * nn
    fh = y[ig + 1]
    h = y[ig + 2]

    # Piezo force with Bouc-Wen hysteresis (eqs. 14, 15).
    fp = prm[KP] * (prm[D33] * volt - h)
    dy[ig + 2] = prm[AP_D33] * dvolt - prm[BP] * abs(dvolt) * h - prm[CP] * dvolt * abs(h)

    # Leuven friction on the main body (eqs. 6-9).
    v1 = y[nn]
    x = abs(v1) * prm[INV_VS]
    # x**2 through pow() would be the single most expensive operation in the step.
    e = x * x if delta_is_two else x ** prm[DELTA]
    s = prm[FC] + prm[FS_MINUS_FC] * np.exp(-e)
    r = abs(fh / s)
    rn = r if n_is_one else r ** prm[FRIC_N]
    # eq. 6 with s(v) = sgn(v) S(v), written with |v| so that v = 0 needs no 0/0
    gdot = v1 - abs(v1) * _sign0(fh) * rn
    dy[ig] = gdot
    dy[ig + 1] = prm[A] * gdot - prm[B] * abs(gdot) * fh - prm[C] * gdot * abs(fh)
    ff = fh + prm[SIGMA1] * gdot + prm[SIGMA2] * v1

    # Structure: q' = v, v' = M^-1 ({Fp - Ff, 0, .., 0, -Fp} - K q - C v).
    f_main = fp - ff
    f_weight = -fp
    for i in range(nn):
        dy[i] = y[nn + i]
        acc = minv_main[i] * f_main + minv_weight[i] * f_weight
        row = i * nn
        for j in range(nn):
            acc -= minv_k[row + j] * y[j] + minv_c[row + j] * y[nn + j]
        dy[nn + i] = acc


@njit(cache=True, fastmath=False, error_model="numpy")
def rk4_kernel(nn, minv_k, minv_c, minv_main, minv_weight, prm, delta_is_two, n_is_one,
               bt, bv, dt, steps, y):
    """Advance ``y`` in place by ``steps`` classical RK4 steps of ``dt`` [s] from t = 0.

    The input is piecewise linear through breakpoints ``bt`` [s], ``bv`` [V] (held constant
    outside them). Breakpoints lie on step boundaries, so the segment that holds the step's
    midpoint holds the whole step: each stage uses V(t0 + c dt) = V(t0) + slope c dt and
    dV/dt = slope exactly. Returns x1 at the end [m].
    """
    dim = y.shape[0]
    k1 = np.empty(dim)
    k2 = np.empty(dim)
    k3 = np.empty(dim)
    k4 = np.empty(dim)
    tmp = np.empty(dim)
    half = 0.5 * dt
    sixth = dt / 6.0
    nb = bt.shape[0]
    seg = 0
    for k in range(steps):
        t0 = k * dt  # not accumulated: keeps breakpoints exactly on step boundaries
        t_mid = t0 + half
        while seg + 1 < nb and bt[seg + 1] <= t_mid:
            seg += 1
        if t_mid < bt[0] or seg + 1 >= nb:
            v0 = bv[seg]
            slope = 0.0
        else:
            slope = (bv[seg + 1] - bv[seg]) / (bt[seg + 1] - bt[seg])
            v0 = bv[seg] + slope * (t0 - bt[seg])

        _rhs(y, v0, slope, nn, minv_k, minv_c, minv_main, minv_weight, prm, delta_is_two, n_is_one, k1)
        for i in range(dim):
            tmp[i] = y[i] + half * k1[i]
        vm = v0 + slope * (0.5 * dt)
        _rhs(tmp, vm, slope, nn, minv_k, minv_c, minv_main, minv_weight, prm, delta_is_two, n_is_one, k2)
        for i in range(dim):
            tmp[i] = y[i] + half * k2[i]
        _rhs(tmp, vm, slope, nn, minv_k, minv_c, minv_main, minv_weight, prm, delta_is_two, n_is_one, k3)
        for i in range(dim):
            tmp[i] = y[i] + dt * k3[i]
        _rhs(tmp, v0 + slope * dt, slope, nn, minv_k, minv_c, minv_main, minv_weight, prm,
             delta_is_two, n_is_one, k4)
        for i in range(dim):
            y[i] += sixth * (k1[i] + 2.0 * (k2[i] + k3[i]) + k4[i])
    return y[0]


@njit(parallel=True, cache=True, fastmath=False, error_model="numpy")
def rk4_sweep_kernel(nn, minv_k, minv_c, minv_main, minv_weight, prm, delta_is_two, n_is_one,
                     bt, bv, dt, steps, out):
    """``rk4_kernel`` over many points in parallel (``prange``, one point per iteration, the
    points shared out among numba's threads): row ``i`` of every 2-D argument is point ``i``'s
    (``minv_k``/``minv_c`` (P, N*N), ``minv_main``/``minv_weight`` (P, N), ``prm`` (P, N_CONST),
    ``bt``/``bv`` (P, nb)); ``delta_is_two``/``n_is_one`` are (P,) booleans. Writes x1(t_end) [m]
    of point ``i`` to ``out[i]``; a point that diverges ends as inf or NaN (no detection, no retry)."""
    for i in prange(out.shape[0]):
        y = np.zeros(2 * nn + 3)
        out[i] = rk4_kernel(nn, minv_k[i], minv_c[i], minv_main[i], minv_weight[i], prm[i],
                            delta_is_two[i], n_is_one[i], bt[i], bv[i], dt, steps, y)


def prepare_many(points, model: str, n_elements: int = 4):
    """``prepare`` for a list of parameter dicts, stacked for :func:`rk4_sweep_kernel`
    (all points must have the same number of nodes)."""
    prepared = [prepare(p, model, n_elements) for p in points]
    nn = prepared[0][0]
    stack = lambda k: np.ascontiguousarray(np.stack([q[k] for q in prepared]))  # noqa: E731
    flags = lambda k: np.array([q[k] for q in prepared], dtype=np.bool_)  # noqa: E731
    return nn, stack(1), stack(2), stack(3), stack(4), stack(5), flags(6), flags(7)


def sweep_x1(points, breakpoints, model: str = "lps", n_elements: int = 4, t_end: float = 10e-3,
             dt: float = 5e-8) -> np.ndarray:
    """x1(t_end) [m] of every point (parameter dicts with ``normal_force`` filled in, and per-point
    breakpoint arrays ``(bt, bv)``, all of one length) from rest, fixed-step RK4 of ``dt`` [s],
    in parallel over numba's threads (``numba.set_num_threads``). Diverged points come back as
    inf or NaN."""
    steps = int(round(t_end / dt))
    args = prepare_many(points, model, n_elements)
    bt = np.ascontiguousarray(np.stack([np.asarray(b[0], float) for b in breakpoints]))
    bv = np.ascontiguousarray(np.stack([np.asarray(b[1], float) for b in breakpoints]))
    out = np.empty(len(points))
    rk4_sweep_kernel(*args, bt, bv, dt, steps, out)
    return out


def structure(p: Mapping[str, float], model: str, n_elements: int = 4):
    """Mass, damping and stiffness matrices (M, C, K) of the ``"lps"`` or ``"dps"`` model [SI].

    LPS (eq. 19): M = diag(m1, m2), K = kp [[1, -1], [-1, 1]], C = βc K.
    DPS (eqs. 16, 17): ``n_elements`` two-node bar elements of length l/n with consistent mass;
    M = Mp + diag(m1, 0, .., 0, m2), C = αc Mp + βc Kp (Rayleigh damping on the PE only).
    """
    if model == "lps":
        kp = p["pe_youngs"] * p["pe_area"] / p["pe_length"]
        k = kp * np.array([[1.0, -1.0], [-1.0, 1.0]])
        return np.diag([p["m1"], p["m2"]]), p["rayleigh_beta"] * k, k
    if model != "dps":
        raise ValueError(f"model must be 'lps' or 'dps', got {model!r}")
    if n_elements < 1:
        raise ValueError(f"n_elements must be at least 1, got {n_elements}")
    nn = n_elements + 1
    le = p["pe_length"] / n_elements
    me = p["pe_density"] * p["pe_area"] * le / 6.0 * np.array([[2.0, 1.0], [1.0, 2.0]])
    ke = p["pe_youngs"] * p["pe_area"] / le * np.array([[1.0, -1.0], [-1.0, 1.0]])
    mp = np.zeros((nn, nn))
    kpm = np.zeros((nn, nn))
    for e in range(n_elements):
        mp[e:e + 2, e:e + 2] += me
        kpm[e:e + 2, e:e + 2] += ke
    m = mp.copy()
    m[0, 0] += p["m1"]
    m[-1, -1] += p["m2"]
    return m, p["rayleigh_alpha"] * mp + p["rayleigh_beta"] * kpm, kpm


def prepare(p: Mapping[str, float], model: str, n_elements: int = 4):
    """Everything the kernel needs except the input and time grid, as a tuple of kernel args:
    (nn, M^-1 K, M^-1 C, M^-1[:, 0], M^-1[:, -1], constants, δ == 2, n == 1)."""
    m, c, k = structure(p, model, n_elements)
    minv = np.linalg.inv(m)
    prm = np.empty(N_CONST)
    prm[KP] = p["pe_youngs"] * p["pe_area"] / p["pe_length"]
    prm[D33] = p["d33"]
    prm[AP_D33] = p["hyst_alpha"] * p["d33"]
    prm[BP] = p["hyst_beta"]
    prm[CP] = p["hyst_gamma"]
    prm[FC] = p["mu_k"] * p["normal_force"]
    prm[FS_MINUS_FC] = (p["mu_s"] - p["mu_k"]) * p["normal_force"]
    prm[INV_VS] = 1.0 / p["stribeck_velocity"]
    prm[DELTA] = p["stribeck_exponent"]
    prm[FRIC_N] = p["fric_n"]
    prm[A] = p["fric_alpha"]
    prm[B] = p["fric_beta"]
    prm[C] = p["fric_gamma"]
    prm[SIGMA1] = p["sigma1"]
    prm[SIGMA2] = p["sigma2"]
    return (
        m.shape[0],
        np.ascontiguousarray((minv @ k).ravel()),
        np.ascontiguousarray((minv @ c).ravel()),
        np.ascontiguousarray(minv[:, 0]),
        np.ascontiguousarray(minv[:, -1]),
        prm,
        p["stribeck_exponent"] == 2.0,
        p["fric_n"] == 1.0,
    )


def triangle_breakpoints(amplitude: float = 80.0, rise: float = 0.5e-3, fall: float = 9.5e-3):
    """Breakpoints (t [s], V [V]) of a single triangle: 0 -> ``amplitude`` over ``rise``, back to
    0 over ``fall``. The defaults are the paper case (80 V, 0.5 ms up, to 0 V at 10 ms)."""
    return np.array([0.0, rise, rise + fall]), np.array([0.0, amplitude, 0.0])


def simulate_x1(p: Mapping[str, float], model: str, n_elements: int = 4, t_end: float = 10e-3,
                dt: float = 1e-8, breakpoints=None) -> float:
    """x1(t_end) [m] from rest under the triangle input (paper case by default), fixed-step RK4
    of ``dt`` [s]. ``p`` is a parameter dict as ``idm_rs.Params().to_dict()`` gives it, with
    ``normal_force`` [N] filled in."""
    if p.get("normal_force") is None:
        raise ValueError("p['normal_force'] must be set (Params().to_dict() fills it in)")
    steps = int(round(t_end / dt))
    bt, bv = triangle_breakpoints() if breakpoints is None else breakpoints
    args = prepare(p, model, n_elements)
    y = np.zeros(2 * args[0] + 3)
    return float(rk4_kernel(*args, np.asarray(bt, float), np.asarray(bv, float), dt, steps, y))


if __name__ == "__main__":
    import idm_rs

    params = idm_rs.Params().to_dict()
    for name, mdl in (("LPS", "lps"), ("DPS4", "dps")):
        print(f"{name}: x1(10 ms) = {simulate_x1(params, mdl):.10e} m")
