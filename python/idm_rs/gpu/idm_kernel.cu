/* The IDM's fixed-step RK4 and adaptive Dormand-Prince for one point per thread: the source of the
 * CUDA sweep backend (compiled by NVRTC through CuPy) and, unchanged, of the CPU build the test
 * suite compiles with the system C compiler to check it against the Rust engine.
 *
 * It holds no physics: the right-hand side `idm_rhs` and the state's layout are generated from the
 * engine's model for the points' shape (rust/src/gpu/generate.rs: Model::rhs_impl traced, every
 * effect and the library forces included) and put in front of this file with the engine's
 * shared header (crawl limits, tableaus: rust/src/gpu/kernel.rs). Specialised at compile time,
 * as DiffEqGPU generates one kernel per ODE, so the state and the stages are fixed-size arrays
 * indexed by constants after unrolling: they live in registers (ptxas -v: 0 bytes stack frame),
 * which tests/test_gpu_kernel.py checks.
 *
 * Inputs: the constants of each distinct parameter row (consts, IDM_NC numbers per row: those the
 * right-hand side reads, IDM_CK, then the integrators' IDM_H_*; point p reads row rows[p],
 * neighbouring points of one row read the same address), and the wave's six numbers as columns:
 * column k of point p is data[off[k] + step[k] * p] (step 1: one value per point, coalesced;
 * step 0: one value for the whole batch). Outputs are columns: out[k * points + p]. */

#if defined(__CUDACC__) || defined(__CUDACC_RTC__)
#define IDM_HD __device__ __forceinline__
#define IDM_KERNEL extern "C" __global__ void __launch_bounds__(IDM_BLOCK)
#define IDM_UNROLL _Pragma("unroll")
#else
#include <math.h>
#define IDM_HD static inline
#define IDM_KERNEL void
#define IDM_UNROLL
#endif

/* IDM_N, IDM_DIM, IDM_NC and the rest of the layout come in front of this file, idm_rhs in place of
 * the marker below (idm_rs.gpu.backend.kernel_source) */
#ifndef IDM_NC
#error "compile with the generated layout in front: idm_rs.gpu.backend.kernel_source(spec)"
#endif

/* A point's constant k, as the generated right-hand side reads it: on the GPU a load the compiler
 * may not hoist out of the step loop (where the constants would crowd the stages out of the
 * registers; the warp's points of one parameter row read one address: an L1 broadcast). */
#if defined(__CUDACC__) || defined(__CUDACC_RTC__)
IDM_HD double idm_ld(const double *p) {
    double v;
    asm volatile("ld.global.nc.f64 %0, [%1];" : "=d"(v) : "l"(p));
    return v;
}
#define IDM_CK(c, k) idm_ld((c) + (k))
/* NVRTC has no INFINITY or NAN */
#define IDM_INF __longlong_as_double(0x7ff0000000000000LL)
#define IDM_NAN __longlong_as_double(0x7ff8000000000000LL)
/* sin and cos through sinpi and cospi: CUDA's sin keeps a 40-byte array on the stack for the
 * reduction of huge arguments, sinpi reduces exactly without one. The argument's division by pi
 * rounds once (a relative 1e-16 of the force term, far inside the kernel's 1e-12 m budget). */
#define IDM_SIN(x) sinpi((x) * 0.31830988618379067154)
#define IDM_COS(x) cospi((x) * 0.31830988618379067154)
#else
#define IDM_CK(c, k) ((c)[k])
#define IDM_INF INFINITY
#define IDM_NAN NAN
#define IDM_SIN(x) sin(x)
#define IDM_COS(x) cos(x)
#endif

/* idm_rhs(c, t, volt, dvolt, y, dy): dy/dt of the state, returning the friction force Ff [N] */
IDM_GENERATED_RHS

#ifndef IDM_BLOCK
#define IDM_BLOCK 128
#endif
/* the wave's columns (waveforms.py: Triangle, Sawtooth) */
#define IDM_W_DELAY 0
#define IDM_W_AMP 1
#define IDM_W_PEAK 2   /* peak time within a cycle: rise (forward), period - rise (backward) [s] */
#define IDM_W_SPAN 3   /* Triangle: fall [s]; Sawtooth: period [s] */
#define IDM_W_CYCLES 4
#define IDM_W_TRIANGLE 5 /* 1 for a Triangle (its end is delay + rise + fall), 0 for a Sawtooth */
#define IDM_NW 6

#if !(defined(__CUDACC__) || defined(__CUDACC_RTC__)) || !defined(IDM_SHARED_STAGES)
#undef IDM_SHARED_STAGES
#define IDM_SHARED_STAGES 0
#endif

/* The piecewise-linear input, evaluated from its few numbers (waveforms.py / physics/waveform.rs:
 * the same arithmetic, so the breakpoints are the engine's to the bit): breakpoint k [s, V]. */
typedef struct {
    double delay, amp, peak, span;
    int nb, off, triangle; /* breakpoints; 1 when a delay adds one at t = delay; the family */
    int sh;                /* the four numbers read from shared memory (IDM_WAVE_SHARED) */
} idm_wave;

/* With IDM_WAVE_SHARED (GPU only) the fixed-step kernel keeps the four numbers the breakpoints
 * are computed from in shared memory (each thread its own column) and reads them there when the
 * cursor moves, a few times per run, instead of holding 8 registers over the whole step loop.
 * The same values. The adaptive kernel keeps them in registers (sh = 0): shared, it was measured
 * slower (H200: 378 k against 599 k points/s). */
#if !(defined(__CUDACC__) || defined(__CUDACC_RTC__)) || !defined(IDM_WAVE_SHARED)
#undef IDM_WAVE_SHARED
#define IDM_WAVE_SHARED 0
#endif
#if IDM_WAVE_SHARED
__shared__ double idm_wsh[4][IDM_BLOCK];
#define IDM_WV(w, f, k) ((w)->sh ? ((volatile double *)idm_wsh[k])[threadIdx.x] : (w)->f)
#else
#define IDM_WV(w, f, k) ((w)->f)
#endif

IDM_HD idm_wave idm_wave_of(const double *w, int sh) {
    idm_wave r;
    r.delay = w[IDM_W_DELAY];
    r.amp = w[IDM_W_AMP];
    r.peak = w[IDM_W_PEAK];
    r.span = w[IDM_W_SPAN];
    r.sh = sh;
#if IDM_WAVE_SHARED
    if (sh) {
        ((volatile double *)idm_wsh[0])[threadIdx.x] = r.delay;
        ((volatile double *)idm_wsh[1])[threadIdx.x] = r.amp;
        ((volatile double *)idm_wsh[2])[threadIdx.x] = r.peak;
        ((volatile double *)idm_wsh[3])[threadIdx.x] = r.span;
    }
#endif
    r.off = r.delay > 0.0 ? 1 : 0;
    r.triangle = w[IDM_W_TRIANGLE] != 0.0;
    r.nb = 1 + r.off + 2 * (int)w[IDM_W_CYCLES];
    return r;
}

IDM_HD void idm_bp(const idm_wave *w, int k, double *t, double *v) {
    if (k <= w->off) {
        *t = k == 0 ? 0.0 : IDM_WV(w, delay, 0);
        *v = 0.0;
        return;
    }
    int j = k - 1 - w->off, cyc = j >> 1;
    if ((j & 1) == 0) {
        *t = IDM_WV(w, delay, 0) + (double)cyc * IDM_WV(w, span, 3) + IDM_WV(w, peak, 2);
        *v = IDM_WV(w, amp, 1);
    } else {
        /* the end of a cycle: delay + rise + fall (Triangle), delay + (cycle + 1) period */
        *t = w->triangle ? IDM_WV(w, delay, 0) + IDM_WV(w, peak, 2) + IDM_WV(w, span, 3)
                         : IDM_WV(w, delay, 0) + (double)(cyc + 1) * IDM_WV(w, span, 3);
        *v = 0.0;
    }
}

/* A cursor on the input: the segment [ta, tb] holding the current time, with its end values. */
typedef struct {
    int seg;
    double ta, va, tb, vb;
} idm_cursor;

IDM_HD void idm_cursor_start(const idm_wave *w, idm_cursor *cu) {
    cu->seg = 0;
    idm_bp(w, 0, &cu->ta, &cu->va);
    idm_bp(w, 1, &cu->tb, &cu->vb);
}

/* move on while the next breakpoint is at or before t (the last segment stays open) */
IDM_HD int idm_cursor_walk(const idm_wave *w, idm_cursor *cu, double t) {
    int moved = 0;
    while (cu->seg + 1 < w->nb && cu->tb <= t) {
        cu->seg++;
        cu->ta = cu->tb;
        cu->va = cu->vb;
        if (cu->seg + 1 < w->nb) idm_bp(w, cu->seg + 1, &cu->tb, &cu->vb);
        moved = 1;
    }
    return moved;
}

/* point p's wave from its columns (data, off, step) */
IDM_HD void idm_load_wave(const double *data, const long long *off, const long long *step, long long p, double *w) {
    IDM_UNROLL
    for (int k = 0; k < IDM_NW; k++) w[k] = data[off[k] + step[k] * p];
}

/* With IDM_METRICS_SHARED (GPU only) the step loop's per-point bounds and running metrics live in
 * shared memory (each thread its own column: a few loads and stores per step, 10 registers
 * less over the loop); else in registers. The same arithmetic. */
#if !(defined(__CUDACC__) || defined(__CUDACC_RTC__)) || !defined(IDM_METRICS_SHARED)
#undef IDM_METRICS_SHARED
#define IDM_METRICS_SHARED 0
#endif
#define IDM_MT_PEAK_V 0
#define IDM_MT_PEAK_F 1
#define IDM_MT_SLIP_T 2
#define IDM_MT_BOUND 3
#define IDM_MT_SLIP_V 4
#if IDM_METRICS_SHARED
__shared__ double idm_msh[5][IDM_BLOCK];
#define IDM_MT(k) (((volatile double *)idm_msh[k])[threadIdx.x])
#else
#define IDM_MT(k) mt[k]
#endif

/* One point: RK4 from rest over `steps` steps of `dt` [s]. Outputs (column k of out, stride
 * `points`): 0 final x1 [m], 1 peak |v1| [m/s], 2 peak |Ff| [N], 3 slip fraction, 4 status (1 ok,
 * 3 diverged), 5 time of divergence [s]. */
IDM_HD void idm_rk4_point(const double *c, const double *wc, double dt, long long steps, double *out,
                          long long points) {
    const int n = IDM_N;
    /* four vectors: the state, the stages' running sum (k1 + 2 k2 + 2 k3, added in the order of
     * integrate/rk4.rs), the latest stage and the stage input */
    double y[IDM_DIM], acc[IDM_DIM], k[IDM_DIM], tmp[IDM_DIM];
    IDM_UNROLL
    for (int i = 0; i < IDM_DIM; i++) y[i] = 0.0;
    idm_wave w = idm_wave_of(wc, 1);
    idm_cursor cu;
    idm_cursor_start(&w, &cu);
#if !IDM_METRICS_SHARED
    double mt[5];
#endif
    IDM_MT(IDM_MT_BOUND) = c[IDM_H_FH_BOUND] * (1.0 + 1e-6) + 1e-12;
    IDM_MT(IDM_MT_SLIP_V) = c[IDM_H_SLIP_V];
    IDM_MT(IDM_MT_PEAK_V) = 0.0;
    IDM_MT(IDM_MT_PEAK_F) = 0.0;
    IDM_MT(IDM_MT_SLIP_T) = 0.0;
    double status = 1.0, div_at = 0.0;
    /* the input's slope on the cursor's segment, computed when the cursor moves (0 on the last) */
    double s = cu.seg + 1 >= w.nb ? 0.0 : (cu.vb - cu.va) / (cu.tb - cu.ta);
    for (long long kk = 0; kk < steps; kk++) {
        double t0 = (double)kk * dt, v0;
        /* the segment holding the step's middle; breakpoints fall on step boundaries (drive/) */
        if (idm_cursor_walk(&w, &cu, t0 + 0.5 * dt)) s = cu.seg + 1 >= w.nb ? 0.0 : (cu.vb - cu.va) / (cu.tb - cu.ta);
        v0 = cu.seg + 1 >= w.nb ? cu.va : cu.va + s * (t0 - cu.ta);
        /* the tableau of rust/src/integrate/tableau.rs (its #defines generated: gpu/kernel.rs) */
        double h2 = IDM_RK4_C2 * dt, h3 = IDM_RK4_C3 * dt, h4 = IDM_RK4_C4 * dt;
        double ff = idm_rhs(c, t0, v0, s, y, k);
        /* the state at the step's start is held over the step (metrics.rs) */
        if (fabs(y[n]) > IDM_MT(IDM_MT_PEAK_V)) IDM_MT(IDM_MT_PEAK_V) = fabs(y[n]);
        if (fabs(ff) > IDM_MT(IDM_MT_PEAK_F)) IDM_MT(IDM_MT_PEAK_F) = fabs(ff);
        if (fabs(y[n]) > IDM_MT(IDM_MT_SLIP_V)) IDM_MT(IDM_MT_SLIP_T) = IDM_MT(IDM_MT_SLIP_T) + dt;
        IDM_UNROLL
        for (int i = 0; i < IDM_DIM; i++) { tmp[i] = y[i] + h2 * k[i]; acc[i] = k[i]; }
        idm_rhs(c, t0 + h2, v0 + s * h2, s, tmp, k);
        IDM_UNROLL
        for (int i = 0; i < IDM_DIM; i++) { tmp[i] = y[i] + h3 * k[i]; acc[i] = acc[i] + IDM_RK4_MIDDLE_WEIGHT * k[i]; }
        idm_rhs(c, t0 + h3, v0 + s * h3, s, tmp, k);
        IDM_UNROLL
        for (int i = 0; i < IDM_DIM; i++) { tmp[i] = y[i] + h4 * k[i]; acc[i] = acc[i] + IDM_RK4_MIDDLE_WEIGHT * k[i]; }
        idm_rhs(c, t0 + h4, v0 + s * h4, s, tmp, k);
        IDM_UNROLL
        for (int i = 0; i < IDM_DIM; i++) y[i] += dt / IDM_RK4_DENOMINATOR * (acc[i] + k[i]);
        if (!(fabs(y[IDM_IFH]) <= IDM_MT(IDM_MT_BOUND)) || !isfinite(y[n]) || !isfinite(y[0])) {
            status = 3.0;
            div_at = (double)(kk + 1) * dt;
            break;
        }
    }
    /* the final state's friction (which reads no input) */
    double ff_end = idm_rhs(c, (double)steps * dt, 0.0, 0.0, y, k);
    double peak_v = IDM_MT(IDM_MT_PEAK_V), peak_f = IDM_MT(IDM_MT_PEAK_F), slip_t = IDM_MT(IDM_MT_SLIP_T);
    if (fabs(y[n]) > peak_v) peak_v = fabs(y[n]);
    if (fabs(ff_end) > peak_f) peak_f = fabs(ff_end);
    out[0] = y[0];
    out[points] = peak_v;
    out[2 * points] = peak_f;
    out[3 * points] = slip_t / ((double)steps * dt);
    out[4 * points] = status;
    out[5 * points] = div_at;
}

/* Dormand-Prince 5(4) with first-same-as-last stages (integrate/dopri5.rs), landing on every breakpoint
 * and on t_end (drive/), error norm in the model's natural units (model/mod.rs: state_scales:
 * positions and h by the free stroke d33 V_max, velocities by stroke x the LPS frequency, Fh by
 * Fs; g left out). Outputs as idm_rk4_point, then 6 accepted steps, 7 smallest step [s], 8 = 1
 * where the run stopped because its step collapsed (integrate/crawl.rs: every IDM_CRAWL_CHECK_STEPS
 * accepted steps, the steps it would need at the pace of the last ones are projected; beyond
 * IDM_MAX_ADAPTIVE_STEPS it stops, status 3 at that time), else 0. */
IDM_HD void idm_dopri5_point(const double *c, const double *wc, double t_end, double rtol,
                             double atol, double first_step, double *out, long long points) {
    /* the tableau of rust/src/integrate/tableau.rs (its #defines generated: gpu/kernel.rs) */
    const double C2 = IDM_DP5_C2, C3 = IDM_DP5_C3, C4 = IDM_DP5_C4, C5 = IDM_DP5_C5;
    const double A21 = IDM_DP5_A21, A31 = IDM_DP5_A31, A32 = IDM_DP5_A32, A41 = IDM_DP5_A41, A42 = IDM_DP5_A42,
                 A43 = IDM_DP5_A43, A51 = IDM_DP5_A51, A52 = IDM_DP5_A52, A53 = IDM_DP5_A53, A54 = IDM_DP5_A54,
                 A61 = IDM_DP5_A61, A62 = IDM_DP5_A62, A63 = IDM_DP5_A63, A64 = IDM_DP5_A64, A65 = IDM_DP5_A65;
    const double B1 = IDM_DP5_B1, B3 = IDM_DP5_B3, B4 = IDM_DP5_B4, B5 = IDM_DP5_B5, B6 = IDM_DP5_B6;
    const double E1 = IDM_DP5_E1, E3 = IDM_DP5_E3, E4 = IDM_DP5_E4, E5 = IDM_DP5_E5, E6 = IDM_DP5_E6, E7 = IDM_DP5_E7;
    const int n = IDM_N;
    /* the state, a stage's input and output and the first stage in registers; the later stages
     * k2..k7 too with IDM_SHARED_STAGES 0, else in shared memory (each thread its own column:
     * conflict-free), where many nodes would not fit beside them; with IDM_SHARED_STAGES 2 the
     * stage's output too (each thread its own row, padded to an odd length: conflict-free), where
     * the largest right-hand sides crowd it out beside the state */
    /* tmp holds each stage's input, then the next state (its last use: one vector fewer) */
#if IDM_SHARED_STAGES >= 2
    double y[IDM_DIM], tmp[IDM_DIM], k1[IDM_DIM];
    __shared__ double idm_kt[IDM_BLOCK][IDM_DIM | 1];
    double *kt = idm_kt[threadIdx.x];
#else
    double y[IDM_DIM], tmp[IDM_DIM], kt[IDM_DIM], k1[IDM_DIM];
#endif
#if IDM_SHARED_STAGES
    __shared__ double idm_ks[6][IDM_DIM][IDM_BLOCK];
#define KS(s, i) idm_ks[(s) - 2][i][threadIdx.x]
#else
    double idm_kr[6][IDM_DIM];
#define KS(s, i) idm_kr[(s) - 2][i]
#endif
    IDM_UNROLL
    for (int i = 0; i < IDM_DIM; i++) y[i] = 0.0;
    idm_wave w = idm_wave_of(wc, 0);
    idm_cursor cu;
    idm_cursor_start(&w, &cu);
    /* the error norm's scales (model/mod.rs: state_scales, from the generated IDM_SCALE_KINDS:
     * 0 out of the norm, 1 the stroke, 2 stroke x the LPS frequency, 3 Fs, 4 the voltage) */
    const int kinds[IDM_DIM] = IDM_SCALE_KINDS;
    double stroke = fmax(c[IDM_H_STROKE_PER_V] * fabs(w.amp), 1e-9);
    const double in_norm = (double)IDM_IN_NORM;
    double h_max = fmax(t_end / 10.0, first_step), h = fmin(first_step, h_max), h_min = 1e-14;
    double t = 0.0, peak_v = 0.0, peak_f = 0.0, slip_t = 0.0, min_step = 1e300;
    double slip_v = c[IDM_H_SLIP_V];
    double ff_prev = idm_rhs(c, 0.0, 0.0, 0.0, y, kt), v_prev = 0.0;
    double status = 1.0, div_at = 0.0, crawled = 0.0;
    long long accepted = 0;
    double t_check = 0.0; /* the time of the last crawl check */
    int fresh = 1;
    while (t < t_end) {
        /* the segment holding t, its end (the next breakpoint or t_end), the input there */
        if (idm_cursor_walk(&w, &cu, t)) fresh = 1; /* the input's slope changed */
        double end = t_end, v0, slope;
        if (cu.seg + 1 < w.nb) {
            end = fmin(cu.tb, t_end);
            slope = (cu.vb - cu.va) / (cu.tb - cu.ta);
            v0 = cu.va + slope * (t - cu.ta);
        } else {
            v0 = cu.va;
            slope = 0.0;
        }
        if (fresh) {
            idm_rhs(c, t, v0, slope, y, k1);
            fresh = 0;
        }
        int last = end - (t + h) < 1e-3 * h;
        double st = last ? end - t : h;
        IDM_UNROLL
        for (int i = 0; i < IDM_DIM; i++) tmp[i] = y[i] + st * (A21 * k1[i]);
        idm_rhs(c, t + C2 * st, v0 + slope * C2 * st, slope, tmp, kt);
        IDM_UNROLL
        for (int i = 0; i < IDM_DIM; i++) KS(2, i) = kt[i];
        IDM_UNROLL
        for (int i = 0; i < IDM_DIM; i++) tmp[i] = y[i] + st * (A31 * k1[i] + A32 * KS(2, i));
        idm_rhs(c, t + C3 * st, v0 + slope * C3 * st, slope, tmp, kt);
        IDM_UNROLL
        for (int i = 0; i < IDM_DIM; i++) KS(3, i) = kt[i];
        IDM_UNROLL
        for (int i = 0; i < IDM_DIM; i++) tmp[i] = y[i] + st * (A41 * k1[i] + A42 * KS(2, i) + A43 * KS(3, i));
        idm_rhs(c, t + C4 * st, v0 + slope * C4 * st, slope, tmp, kt);
        IDM_UNROLL
        for (int i = 0; i < IDM_DIM; i++) KS(4, i) = kt[i];
        IDM_UNROLL
        for (int i = 0; i < IDM_DIM; i++) tmp[i] = y[i] + st * (A51 * k1[i] + A52 * KS(2, i) + A53 * KS(3, i) + A54 * KS(4, i));
        idm_rhs(c, t + C5 * st, v0 + slope * C5 * st, slope, tmp, kt);
        IDM_UNROLL
        for (int i = 0; i < IDM_DIM; i++) KS(5, i) = kt[i];
        IDM_UNROLL
        for (int i = 0; i < IDM_DIM; i++)
            tmp[i] = y[i] + st * (A61 * k1[i] + A62 * KS(2, i) + A63 * KS(3, i) + A64 * KS(4, i) + A65 * KS(5, i));
        idm_rhs(c, t + st, v0 + slope * st, slope, tmp, kt);
        IDM_UNROLL
        for (int i = 0; i < IDM_DIM; i++) KS(6, i) = kt[i];
        IDM_UNROLL
        for (int i = 0; i < IDM_DIM; i++)
            tmp[i] = y[i] + st * (B1 * k1[i] + B3 * KS(3, i) + B4 * KS(4, i) + B5 * KS(5, i) + B6 * KS(6, i));
        idm_rhs(c, t + st, v0 + slope * st, slope, tmp, kt);
        IDM_UNROLL
        for (int i = 0; i < IDM_DIM; i++) KS(7, i) = kt[i];
        double err2 = 0.0;
        IDM_UNROLL
        for (int i = 0; i < IDM_DIM; i++) {
            if (kinds[i] == 0) continue; /* g and what else is out of the norm */
            /* kinds[i] is known after unrolling: one expression per component, nothing held */
            double sc = kinds[i] == 1 ? stroke
                        : kinds[i] == 2 ? stroke * c[IDM_H_OMEGA]
                        : kinds[i] == 3 ? c[IDM_H_FS] : fmax(fabs(w.amp), 1.0);
            double e = E1 * k1[i] + E3 * KS(3, i) + E4 * KS(4, i) + E5 * KS(5, i) + E6 * KS(6, i) + E7 * KS(7, i);
            double tol = atol * sc + rtol * fmax(fabs(y[i]), fabs(tmp[i]));
            err2 += (st * e / tol) * (st * e / tol);
        }
        double err = sqrt(err2 / in_norm);
        if (err <= 1.0) {
            /* the state at the step's start is held over it (metrics.rs, without a start eval) */
            if (fabs(v_prev) > peak_v) peak_v = fabs(v_prev);
            if (fabs(ff_prev) > peak_f) peak_f = fabs(ff_prev);
            double t_new = last ? end : t + st;
            if (fabs(v_prev) > slip_v) slip_t += t_new - t;
            min_step = fmin(min_step, t_new - t);
            t = t_new;
            IDM_UNROLL
            for (int i = 0; i < IDM_DIM; i++) {
                y[i] = tmp[i];
                k1[i] = KS(7, i);
            }
            accepted++;
            double grow = err == 0.0 ? 5.0 : fmin(fmax(0.9 * pow(err, -0.2), 0.2), 5.0);
            if (!last || grow < 1.0) h = fmin(st * grow, h_max);
            if (!isfinite(y[n]) || !isfinite(y[0]) || !isfinite(y[IDM_IFH])) {
                status = 3.0;
                div_at = t;
                break;
            }
            v_prev = y[n];
            ff_prev = idm_rhs(c, t, v0, slope, y, kt);
            if (accepted % IDM_CRAWL_CHECK_STEPS == 0) {
                double pace = (t - t_check) / (double)IDM_CRAWL_CHECK_STEPS;
                t_check = t;
                /* true too for a pace of 0 (no progress): the comparison fails */
                if (!((double)accepted + (t_end - t) / pace <= IDM_MAX_ADAPTIVE_STEPS)) {
                    status = 3.0;
                    div_at = t;
                    crawled = 1.0;
                    break;
                }
            }
        } else {
            double shrink = isfinite(err) ? fmin(fmax(0.9 * pow(err, -0.2), 0.1), 0.9) : 0.1;
            h = st * shrink;
            if (h < h_min) {
                status = 3.0;
                div_at = t;
                break;
            }
        }
    }
    if (fabs(y[n]) > peak_v) peak_v = fabs(y[n]);
    if (fabs(ff_prev) > peak_f) peak_f = fabs(ff_prev);
    out[0] = y[0];
    out[points] = peak_v;
    out[2 * points] = peak_f;
    out[3 * points] = slip_t / t_end;
    out[4 * points] = status;
    out[5 * points] = div_at;
    out[6 * points] = (double)accepted;
    out[7 * points] = min_step;
    out[8 * points] = crawled;
}

/* The fixed-step sweep: thread p runs point p (neighbouring grid points share a warp) with the
 * constants of its parameter row (consts + rows[p] * IDM_NC) and its wave (data, off, step: IDM_NW columns), `steps` steps of dt [s]; outputs
 * column by column in out (6 x points). */
IDM_KERNEL idm_rk4_sweep(const double *__restrict__ consts, const int *__restrict__ rows,
                         const double *__restrict__ data, const long long *__restrict__ off,
                         const long long *__restrict__ step, double dt, long long steps, long long first,
                         long long points, double *__restrict__ out) {
#if defined(__CUDACC__) || defined(__CUDACC_RTC__)
    long long p = first + (long long)blockIdx.x * blockDim.x + threadIdx.x;
    if (p >= points) return;
#else
    for (long long p = first; p < points; p++)
#endif
    {
        double w[IDM_NW];
        idm_load_wave(data, off, step, p, w);
        idm_rk4_point(consts + (long long)rows[p] * IDM_NC, w, dt, steps, out + p, points);
    }
}

/* The adaptive sweep: as idm_rk4_sweep, with t_end [s], the tolerances and the first step [s];
 * outputs 9 x points. */
IDM_KERNEL idm_dopri5_sweep(const double *__restrict__ consts, const int *__restrict__ rows,
                            const double *__restrict__ data, const long long *__restrict__ off,
                            const long long *__restrict__ step, double t_end, double rtol, double atol,
                            double first_step, long long first, long long points, double *__restrict__ out) {
#if defined(__CUDACC__) || defined(__CUDACC_RTC__)
    long long p = first + (long long)blockIdx.x * blockDim.x + threadIdx.x;
    if (p >= points) return;
#else
    for (long long p = first; p < points; p++)
#endif
    {
        double w[IDM_NW];
        idm_load_wave(data, off, step, p, w);
        idm_dopri5_point(consts + (long long)rows[p] * IDM_NC, w, t_end, rtol, atol, first_step, out + p, points);
    }
}
