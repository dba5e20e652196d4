/* The IDM's physics and a fixed-step RK4 for one point per thread: the source of the CUDA
 * sweep backend (compiled by NVRTC through CuPy) and, unchanged, of the CPU build the test suite
 * compiles with the system C compiler to check it against the Rust engine.
 *
 * It mirrors rust/src/model.rs for the models the kernel supports: the LPS or the DPS with up
 * to IDM_MAX_DOF nodes, Leuven friction, Bouc-Wen piezo hysteresis on or off, no effects. The
 * per-point constants come from the engine (rust/src/kernel.rs, in this order). */

#if defined(__CUDACC__) || defined(__CUDACC_RTC__)
#define IDM_HD __device__ __forceinline__
#define IDM_KERNEL extern "C" __global__
#else
#include <math.h>
#define IDM_HD static inline
#define IDM_KERNEL
#endif

#define IDM_MAX_DOF 6
#define IDM_N_SCALARS 19
#define IDM_N_CONSTANTS (IDM_N_SCALARS + 2 * IDM_MAX_DOF * IDM_MAX_DOF + 2 * IDM_MAX_DOF)
#define IDM_DIM (2 * IDM_MAX_DOF + 3)
/* the slip threshold of the slip-fraction metric, in units of the Stribeck velocity */
#define IDM_SLIP_FACTOR 0.1

IDM_HD double idm_sign0(double x) { return x > 0.0 ? 1.0 : (x < 0.0 ? -1.0 : 0.0); }

/* Stribeck curve S(v) [N] (friction.rs: Leuven::stribeck) */
IDM_HD double idm_stribeck(const double *c, double v) {
    double fc = c[3], fs_fc = c[4], inv_vs = c[5], delta = c[6], eps = c[13];
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
    int n = (int)c[0];
    double kp = c[1], d33 = c[2];
    double fric_n = c[7], a = c[8], b = c[9], cc = c[10], sigma1 = c[11], sigma2 = c[12];
    const double *mk = c + IDM_N_SCALARS;
    const double *mc = mk + IDM_MAX_DOF * IDM_MAX_DOF;
    const double *m0 = mc + IDM_MAX_DOF * IDM_MAX_DOF;
    const double *ml = m0 + IDM_MAX_DOF;
    int ig = 2 * n, ifh = 2 * n + 1, ih = 2 * n + 2;
    double h = y[ih];
    dy[ih] = (c[14] != 0.0) ? c[15] * dvolt - c[16] * fabs(dvolt) * h - c[17] * dvolt * fabs(h) : 0.0;
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
    int n = (int)c[0];
    int dim = 2 * n + 3;
    double y[IDM_DIM], k1[IDM_DIM], k2[IDM_DIM], k3[IDM_DIM], k4[IDM_DIM], tmp[IDM_DIM];
    for (int i = 0; i < dim; i++) y[i] = 0.0;
    double bound = c[18] * (1.0 + 1e-6) + 1e-12;
    double slip_v = IDM_SLIP_FACTOR / c[5];
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
