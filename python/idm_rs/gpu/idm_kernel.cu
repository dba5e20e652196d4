/* The IDM's physics, a fixed-step RK4 and an adaptive Dormand-Prince for one point per thread: the source of the CUDA
 * sweep backend (compiled by NVRTC through CuPy) and, unchanged, of the CPU build the test suite
 * compiles with the system C compiler to check it against the Rust engine.
 *
 * It mirrors rust/src/model.rs for the models the kernel supports: the LPS or the DPS with up
 * to IDM_MAX_DOF nodes, Leuven friction, Bouc-Wen piezo hysteresis on or off, no effects. The
 * per-point constants come from the engine (rust/src/kernel.rs), read by name. */

#if defined(__CUDACC__) || defined(__CUDACC_RTC__)
#define IDM_HD __device__ __forceinline__
#define IDM_KERNEL extern "C" __global__
#else
#include <math.h>
#define IDM_HD static inline
#define IDM_KERNEL
#endif

/* IDM_MAX_DOF, IDM_N_SCALARS and the offset of each constant by name come from the
 * engine (rust/src/kernel.rs: kernel_header), put in front of this source when it is compiled */
#ifndef IDM_N_SCALARS
#error "compile with the engine's header in front: idm_rs.engine.kernel_header()"
#endif
#define IDM_N_CONSTANTS (IDM_N_SCALARS + 2 * IDM_MAX_DOF * IDM_MAX_DOF + 2 * IDM_MAX_DOF)
#define IDM_DIM (2 * IDM_MAX_DOF + 3)
/* the slip threshold of the slip-fraction metric, in units of the Stribeck velocity */
#define IDM_SLIP_FACTOR 0.1

IDM_HD double idm_sign0(double x) { return x > 0.0 ? 1.0 : (x < 0.0 ? -1.0 : 0.0); }

/* Stribeck curve S(v) [N] (friction.rs: Leuven::stribeck) */
IDM_HD double idm_stribeck(const double *c, double v) {
    double fc = c[IDM_C_FC], fs_fc = c[IDM_C_FS_FC], inv_vs = c[IDM_C_INV_VS], delta = c[IDM_C_DELTA], eps = c[IDM_C_EPS];
    double s;
    if (fs_fc == 0.0) {
        s = fc;
    } else {
        double x = fabs(v) * inv_vs;
        double e = (delta == 2.0) ? x * x : pow(x, delta);
        s = fc + fs_fc * exp(-e);
    }
    return eps == 0.0 ? s : s * (1.0 + eps * idm_sign0(v));
}

/* dy/dt of the plain state [q (n), v (n), g, Fh, h] at voltage volt rising at dvolt;
 * returns the friction force Ff [N] (model.rs: Model::rhs_impl without effects). */
IDM_HD double idm_rhs(const double *c, double volt, double dvolt, const double *y, double *dy) {
    int n = (int)c[IDM_C_DOF];
    double kp = c[IDM_C_KP], d33 = c[IDM_C_D33];
    double fric_n = c[IDM_C_FRIC_N], a = c[IDM_C_A], b = c[IDM_C_B], cc = c[IDM_C_C], sigma1 = c[IDM_C_SIGMA1], sigma2 = c[IDM_C_SIGMA2];
    const double *mk = c + IDM_N_SCALARS;
    const double *mc = mk + IDM_MAX_DOF * IDM_MAX_DOF;
    const double *m0 = mc + IDM_MAX_DOF * IDM_MAX_DOF;
    const double *ml = m0 + IDM_MAX_DOF;
    int ig = 2 * n, ifh = 2 * n + 1, ih = 2 * n + 2;
    double h = y[ih];
    dy[ih] = (c[IDM_C_HYST_ON] != 0.0) ? c[IDM_C_HYST_AP_D33] * dvolt - c[IDM_C_HYST_BP] * fabs(dvolt) * h - c[IDM_C_HYST_CP] * dvolt * fabs(h) : 0.0;
    double fp = kp * (d33 * volt + 0.0 - h);
    double v1 = y[n], fh = y[ifh];
    double ratio = fh / idm_stribeck(c, v1);
    double gdot = (fric_n == 1.0) ? v1 - fabs(v1) * ratio
                                  : v1 - fabs(v1) * idm_sign0(fh) * pow(fabs(ratio), fric_n);
    double fhdot = a * gdot - b * fabs(gdot) * fh - cc * gdot * fabs(fh);
    double ff = (fh + sigma2 * v1) + sigma1 * gdot;
    dy[ig] = gdot;
    dy[ifh] = fhdot;
    double f_main = (fp + 0.0) - ff, f_weight = 0.0 - fp;
    for (int i = 0; i < n; i++) dy[i] = y[n + i];
    for (int i = 0; i < n; i++) {
        double acc = 0.0;
        for (int j = 0; j < n; j++) acc -= mk[i * IDM_MAX_DOF + j] * y[j] + mc[i * IDM_MAX_DOF + j] * y[n + j];
        dy[n + i] = acc + ml[i] * f_weight + m0[i] * f_main;
    }
    return ff;
}

/* The input at the start of step k (t0 = k dt) and its slope over the step, from the breakpoints
 * (bt, bv; nb of them), which fall on step boundaries; *seg walks forward (drive.rs + Cursor). */
IDM_HD void idm_input(const double *bt, const double *bv, int nb, int *seg, double t0, double dt,
                      double *v0, double *slope) {
    double probe = t0 + 0.5 * dt;
    while (*seg + 1 < nb && bt[*seg + 1] <= probe) (*seg)++;
    if (probe < bt[0] || *seg + 1 >= nb) {
        *v0 = (probe < bt[0]) ? bv[0] : bv[nb - 1];
        *slope = 0.0;
        return;
    }
    int s = *seg;
    *slope = (bv[s + 1] - bv[s]) / (bt[s + 1] - bt[s]);
    *v0 = bv[s] + *slope * (t0 - bt[s]);
}

/* One point: RK4 from rest over `steps` steps of `dt` under the input (bt, bv). out[0..5]:
 * final x1 [m], peak |v1| [m/s], peak |Ff| [N], slip fraction, status (1 ok, 3 diverged),
 * time of divergence [s]. */
IDM_HD void idm_rk4_point(const double *c, const double *bt, const double *bv, int nb, double dt, long steps,
                          double *out) {
    int n = (int)c[IDM_C_DOF];
    int dim = 2 * n + 3;
    double y[IDM_DIM], k1[IDM_DIM], k2[IDM_DIM], k3[IDM_DIM], k4[IDM_DIM], tmp[IDM_DIM];
    for (int i = 0; i < dim; i++) y[i] = 0.0;
    double bound = c[IDM_C_FH_BOUND] * (1.0 + 1e-6) + 1e-12;
    double slip_v = IDM_SLIP_FACTOR / c[IDM_C_INV_VS];
    double peak_v = 0.0, peak_f = 0.0, slip_t = 0.0;
    int seg = 0;
    out[4] = 1.0;
    out[5] = 0.0;
    for (long k = 0; k < steps; k++) {
        double t0 = (double)k * dt, v0, s;
        idm_input(bt, bv, nb, &seg, t0, dt, &v0, &s);
        double h2 = 0.5 * dt;
        double ff = idm_rhs(c, v0, s, y, k1);
        /* the state at the step's start is held over the step (metrics.rs) */
        if (fabs(y[n]) > peak_v) peak_v = fabs(y[n]);
        if (fabs(ff) > peak_f) peak_f = fabs(ff);
        if (fabs(y[n]) > slip_v) slip_t += dt;
        for (int i = 0; i < dim; i++) tmp[i] = y[i] + h2 * k1[i];
        idm_rhs(c, v0 + s * h2, s, tmp, k2);
        for (int i = 0; i < dim; i++) tmp[i] = y[i] + h2 * k2[i];
        idm_rhs(c, v0 + s * h2, s, tmp, k3);
        for (int i = 0; i < dim; i++) tmp[i] = y[i] + dt * k3[i];
        idm_rhs(c, v0 + s * dt, s, tmp, k4);
        for (int i = 0; i < dim; i++) y[i] += dt / 6.0 * (k1[i] + 2.0 * k2[i] + 2.0 * k3[i] + k4[i]);
        if (!(fabs(y[2 * n + 1]) <= bound) || !isfinite(y[n]) || !isfinite(y[0])) {
            out[4] = 3.0;
            out[5] = (double)(k + 1) * dt;
            break;
        }
    }
    double yend[IDM_DIM], dummy[IDM_DIM];
    for (int i = 0; i < dim; i++) yend[i] = y[i];
    double ff_end = idm_rhs(c, bv[nb - 1], 0.0, yend, dummy);
    if (fabs(y[n]) > peak_v) peak_v = fabs(y[n]);
    if (fabs(ff_end) > peak_f) peak_f = fabs(ff_end);
    out[0] = y[0];
    out[1] = peak_v;
    out[2] = peak_f;
    out[3] = slip_t / ((double)steps * dt);
}

/* Dormand-Prince 5(4) with first-same-as-last stages (dopri5.rs), landing on every breakpoint
 * and on t_end (drive.rs), error norm in the model's natural units (model.rs: state_scales:
 * positions and h by the free stroke d33 V_max, velocities by stroke x the LPS frequency, Fh by
 * Fs; g left out). out as idm_rk4_point; out[6] = accepted steps, out[7] = smallest step,
 * out[8] = 1 where the run stopped because its step collapsed (crawl.rs: every
 * IDM_CRAWL_CHECK_STEPS accepted steps, the steps it would need at the pace of the last ones
 * are projected; beyond IDM_MAX_ADAPTIVE_STEPS it stops, status 3 at that time), else 0. */
IDM_HD void idm_dopri5_point(const double *c, const double *bt, const double *bv, int nb, double t_end,
                             double rtol, double atol, double first_step, double *out) {
    const double C2 = 1.0 / 5.0, C3 = 3.0 / 10.0, C4 = 4.0 / 5.0, C5 = 8.0 / 9.0;
    const double A21 = 1.0 / 5.0, A31 = 3.0 / 40.0, A32 = 9.0 / 40.0, A41 = 44.0 / 45.0, A42 = -56.0 / 15.0,
                 A43 = 32.0 / 9.0, A51 = 19372.0 / 6561.0, A52 = -25360.0 / 2187.0, A53 = 64448.0 / 6561.0,
                 A54 = -212.0 / 729.0, A61 = 9017.0 / 3168.0, A62 = -355.0 / 33.0, A63 = 46732.0 / 5247.0,
                 A64 = 49.0 / 176.0, A65 = -5103.0 / 18656.0;
    const double B1 = 35.0 / 384.0, B3 = 500.0 / 1113.0, B4 = 125.0 / 192.0, B5 = -2187.0 / 6784.0, B6 = 11.0 / 84.0;
    const double E1 = 71.0 / 57600.0, E3 = -71.0 / 16695.0, E4 = 71.0 / 1920.0, E5 = -17253.0 / 339200.0,
                 E6 = 22.0 / 525.0, E7 = -1.0 / 40.0;
    int n = (int)c[IDM_C_DOF];
    int dim = 2 * n + 3;
    double y[IDM_DIM], yn[IDM_DIM], tmp[IDM_DIM], k[7][IDM_DIM], scale[IDM_DIM];
    for (int i = 0; i < dim; i++) y[i] = 0.0;
    double vmax = 0.0;
    for (int i = 0; i < nb; i++) vmax = fmax(vmax, fabs(bv[i]));
    double stroke = fmax(c[IDM_C_D33] * vmax, 1e-9), fs = c[IDM_C_FC] + fmax(c[IDM_C_FS_FC], 0.0);
    int in_norm = 0;
    for (int i = 0; i < dim; i++) scale[i] = -1.0; /* out of the norm */
    for (int i = 0; i < n; i++) { scale[i] = stroke; scale[n + i] = stroke * c[IDM_C_OMEGA_LPS]; }
    scale[2 * n + 1] = fs;
    scale[2 * n + 2] = stroke;
    for (int i = 0; i < dim; i++) in_norm += scale[i] > 0.0;
    double h_max = fmax(t_end / 10.0, first_step), h = fmin(first_step, h_max), h_min = 1e-14;
    double t = 0.0, peak_v = 0.0, peak_f = 0.0, slip_t = 0.0, min_step = 1e300, slip_v = IDM_SLIP_FACTOR / c[IDM_C_INV_VS];
    double ydummy[IDM_DIM];
    double ff_prev = idm_rhs(c, 0.0, 0.0, y, ydummy), v_prev = 0.0;
    long accepted = 0;
    double t_check = 0.0; /* the time of the last crawl check */
    int seg = 0, fresh = 1;
    out[4] = 1.0;
    out[5] = 0.0;
    out[8] = 0.0;
    while (t < t_end) {
        /* the segment holding t, its end (the next breakpoint or t_end), the input there */
        int s0 = seg;
        while (seg + 1 < nb && bt[seg + 1] <= t) seg++;
        if (seg != s0) fresh = 1; /* the input's slope changed */
        double end = t_end, v0, slope;
        if (t < bt[0]) { end = fmin(bt[0], t_end); v0 = bv[0]; slope = 0.0; }
        else if (seg + 1 < nb) {
            end = fmin(bt[seg + 1], t_end);
            slope = (bv[seg + 1] - bv[seg]) / (bt[seg + 1] - bt[seg]);
            v0 = bv[seg] + slope * (t - bt[seg]);
        } else { v0 = bv[nb - 1]; slope = 0.0; }
        if (fresh) { idm_rhs(c, v0, slope, y, k[0]); fresh = 0; }
        int last = end - (t + h) < 1e-3 * h;
        double st = last ? end - t : h;
        for (int i = 0; i < dim; i++) tmp[i] = y[i] + st * (A21 * k[0][i]);
        idm_rhs(c, v0 + slope * C2 * st, slope, tmp, k[1]);
        for (int i = 0; i < dim; i++) tmp[i] = y[i] + st * (A31 * k[0][i] + A32 * k[1][i]);
        idm_rhs(c, v0 + slope * C3 * st, slope, tmp, k[2]);
        for (int i = 0; i < dim; i++) tmp[i] = y[i] + st * (A41 * k[0][i] + A42 * k[1][i] + A43 * k[2][i]);
        idm_rhs(c, v0 + slope * C4 * st, slope, tmp, k[3]);
        for (int i = 0; i < dim; i++)
            tmp[i] = y[i] + st * (A51 * k[0][i] + A52 * k[1][i] + A53 * k[2][i] + A54 * k[3][i]);
        idm_rhs(c, v0 + slope * C5 * st, slope, tmp, k[4]);
        for (int i = 0; i < dim; i++)
            tmp[i] = y[i] + st * (A61 * k[0][i] + A62 * k[1][i] + A63 * k[2][i] + A64 * k[3][i] + A65 * k[4][i]);
        idm_rhs(c, v0 + slope * st, slope, tmp, k[5]);
        for (int i = 0; i < dim; i++)
            yn[i] = y[i] + st * (B1 * k[0][i] + 0.0 * k[1][i] + B3 * k[2][i] + B4 * k[3][i] + B5 * k[4][i] + B6 * k[5][i]);
        idm_rhs(c, v0 + slope * st, slope, yn, k[6]);
        double err2 = 0.0;
        for (int i = 0; i < dim; i++) {
            if (scale[i] > 0.0) {
                double e = E1 * k[0][i] + 0.0 * k[1][i] + E3 * k[2][i] + E4 * k[3][i] + E5 * k[4][i] + E6 * k[5][i]
                           + E7 * k[6][i];
                double tol = atol * scale[i] + rtol * fmax(fabs(y[i]), fabs(yn[i]));
                err2 += (st * e / tol) * (st * e / tol);
            }
        }
        double err = sqrt(err2 / (in_norm > 0 ? in_norm : 1));
        if (err <= 1.0) {
            /* the state at the step's start is held over it (metrics.rs, without a start eval) */
            if (fabs(v_prev) > peak_v) peak_v = fabs(v_prev);
            if (fabs(ff_prev) > peak_f) peak_f = fabs(ff_prev);
            if (fabs(v_prev) > slip_v) slip_t += (last ? end : t + st) - t;
            double t_new = last ? end : t + st;
            min_step = fmin(min_step, t_new - t);
            t = t_new;
            for (int i = 0; i < dim; i++) { y[i] = yn[i]; k[0][i] = k[6][i]; }
            accepted++;
            double grow = err == 0.0 ? 5.0 : fmin(fmax(0.9 * pow(err, -0.2), 0.2), 5.0);
            if (!last || grow < 1.0) h = fmin(st * grow, h_max);
            if (!isfinite(y[n]) || !isfinite(y[0]) || !(fabs(y[2 * n + 1]) <= INFINITY)) {
                out[4] = 3.0; out[5] = t; break;
            }
            v_prev = y[n];
            ff_prev = idm_rhs(c, v0, slope, y, ydummy);
            if (accepted % IDM_CRAWL_CHECK_STEPS == 0) {
                double pace = (t - t_check) / (double)IDM_CRAWL_CHECK_STEPS;
                t_check = t;
                /* true too for a pace of 0 (no progress): the comparison fails */
                if (!((double)accepted + (t_end - t) / pace <= IDM_MAX_ADAPTIVE_STEPS)) {
                    out[4] = 3.0; out[5] = t; out[8] = 1.0; break;
                }
            }
        } else {
            double shrink = isfinite(err) ? fmin(fmax(0.9 * pow(err, -0.2), 0.1), 0.9) : 0.1;
            h = st * shrink;
            if (h < h_min) { out[4] = 3.0; out[5] = t; break; }
        }
    }
    if (fabs(y[n]) > peak_v) peak_v = fabs(y[n]);
    if (fabs(ff_prev) > peak_f) peak_f = fabs(ff_prev);
    out[0] = y[0];
    out[1] = peak_v;
    out[2] = peak_f;
    out[3] = slip_t / t_end;
    out[6] = (double)accepted;
    out[7] = min_step;
}

/* The adaptive sweep: as idm_rk4_sweep, with t_end, tolerances and the first step; 9 outputs. */
IDM_KERNEL void idm_dopri5_sweep(const double *consts, const double *bt, const double *bv, const int *nb, int max_nb,
                                 double t_end, double rtol, double atol, double first_step, int points, double *out) {
#if defined(__CUDACC__) || defined(__CUDACC_RTC__)
    int p = blockIdx.x * blockDim.x + threadIdx.x;
    if (p >= points) return;
    idm_dopri5_point(consts + (long)p * IDM_N_CONSTANTS, bt + (long)p * max_nb, bv + (long)p * max_nb, nb[p], t_end,
                     rtol, atol, first_step, out + (long)p * 9);
#else
    for (int p = 0; p < points; p++)
        idm_dopri5_point(consts + (long)p * IDM_N_CONSTANTS, bt + (long)p * max_nb, bv + (long)p * max_nb, nb[p],
                         t_end, rtol, atol, first_step, out + (long)p * 9);
#endif
}

/* The sweep: thread p runs point p with its constants (row p of consts), its breakpoints (row
 * p of bt/bv, nb[p] of them, padded to max_nb) and its step count; results in row p of out. */
IDM_KERNEL void idm_rk4_sweep(const double *consts, const double *bt, const double *bv, const int *nb, int max_nb,
                              double dt, const long *steps, int points, double *out) {
#if defined(__CUDACC__) || defined(__CUDACC_RTC__)
    int p = blockIdx.x * blockDim.x + threadIdx.x;
    if (p >= points) return;
    idm_rk4_point(consts + (long)p * IDM_N_CONSTANTS, bt + (long)p * max_nb, bv + (long)p * max_nb, nb[p], dt,
                  steps[p], out + (long)p * 6);
#else
    for (int p = 0; p < points; p++)
        idm_rk4_point(consts + (long)p * IDM_N_CONSTANTS, bt + (long)p * max_nb, bv + (long)p * max_nb, nb[p], dt,
                      steps[p], out + (long)p * 6);
#endif
}
