//! The right-hand side of `L` plain models at once, as vector arithmetic: every quantity of the
//! physics is an `[f64; L]` (one value per lane) and every operation a loop over the lanes that
//! the compiler turns into SIMD instructions of the width the processor has (the caller runs it
//! under `pulp`'s runtime dispatch, see `drive.rs`). The arithmetic per lane is that of
//! `Model::rhs_impl` operation for operation, so a lane's result is bitwise that of the scalar
//! model; the one exception is `exp`, which is the C library's per lane by default ([`LibmExp`],
//! bitwise) or a vectorised polynomial ([`PolyExp`], within 2 ulp; see `fast_exp`).
//!
//! Supported: plain states (nodes, g, Fh, h) of the piezo-driven IDM with the effects that add
//! no state (incline, load, a spring to ground, weight drag, friction asymmetry), piezo
//! hysteresis on or off, `fric_n = 1` and a Stribeck exponent of 2 (or no Stribeck peak) in every
//! lane. Anything else runs lane by lane through the scalar model ([`PlainLanes::new`] says so
//! by returning `None`).

use std::sync::atomic::{AtomicBool, Ordering};

use crate::drive::{LaneInputs, ModelRhs, Observer, Task};
use crate::fast_exp::exp_poly;
use crate::mechanics::Actuator;
use crate::model::Model;
use crate::stepper::{Rhs, State};

/// How a lane's `exp` is computed.
pub trait LaneExp: Copy + Send + Sync + 'static {
    fn exp(x: f64) -> f64;
}

/// The C library's `exp`, one lane at a time: bitwise the scalar model's.
#[derive(Clone, Copy, Debug, Default)]
pub struct LibmExp;
impl LaneExp for LibmExp {
    #[inline(always)]
    fn exp(x: f64) -> f64 {
        x.exp()
    }
}

/// A branch-free polynomial `exp` that vectorises (see `fast_exp`).
#[derive(Clone, Copy, Debug, Default)]
pub struct PolyExp;
impl LaneExp for PolyExp {
    #[inline(always)]
    fn exp(x: f64) -> f64 {
        exp_poly(x)
    }
}

/// `[f64; L]` per quantity; `N` nodes.
#[derive(Clone, Debug)]
pub struct PlainLanes<const N: usize, const L: usize> {
    kp: [f64; L],
    d33: [f64; L],
    fc: [f64; L],
    fs_minus_fc: [f64; L],
    inv_vs: [f64; L],
    a: [f64; L],
    b: [f64; L],
    c: [f64; L],
    sigma1: [f64; L],
    sigma2: [f64; L],
    eps: [f64; L],
    hyst: [[f64; L]; 3],
    f_constant: [f64; L],
    k_ground: [f64; L],
    c_weight: [f64; L],
    minv_k: [[[f64; L]; N]; N],
    minv_c: [[[f64; L]; N]; N],
    minv_main: [[f64; L]; N],
    minv_weight: [[f64; L]; N],
    /// some lane has piezo hysteresis / asymmetric friction (else those terms are skipped, as
    /// the scalar model skips them)
    any_hysteresis: bool,
    asymmetric: [bool; L],
    any_asymmetric: bool,
    hysteresis_on: [bool; L],
}

impl<const N: usize, const L: usize> PlainLanes<N, L> {
    /// Whether the vector path computes `m` exactly as the scalar model does (see the module's
    /// documentation).
    pub fn accepts(m: &Model) -> bool {
        let f = m.friction.constants();
        let (fs_fc, delta, n) = (f[1], f[3], f[4]);
        m.is_plain()
            && m.external.is_none()
            && m.library == (false, false)
            && m.layout.dof == N
            && matches!(m.actuator, Actuator::Piezo(_))
            && n == 1.0
            && (fs_fc == 0.0 || delta == 2.0)
    }

    /// The lanes' constants, or `None` when some model is outside what the vector path computes
    /// exactly like the scalar model.
    pub fn new(models: &[&Model; L]) -> Option<Self> {
        if !models.iter().all(|m| Self::accepts(m)) {
            return None;
        }
        let mut p = Self::zeroed();
        for (i, m) in models.iter().enumerate() {
            p.set(i, m);
        }
        Some(p)
    }

    fn zeroed() -> Self {
        let z = [0.0; L];
        PlainLanes {
            kp: z, d33: z, fc: z, fs_minus_fc: z, inv_vs: z, a: z, b: z, c: z, sigma1: z, sigma2: z, eps: z,
            hyst: [z; 3], f_constant: z, k_ground: z, c_weight: z,
            minv_k: [[z; N]; N], minv_c: [[z; N]; N], minv_main: [z; N], minv_weight: [z; N],
            any_hysteresis: false, asymmetric: [false; L], any_asymmetric: false, hysteresis_on: [false; L],
        }
    }

    /// Put model `m` (which [`PlainLanes::accepts`]) on lane `i`.
    pub fn set(&mut self, i: usize, m: &Model) {
        debug_assert!(Self::accepts(m));
        let f = m.friction.constants();
        (self.fc[i], self.fs_minus_fc[i], self.inv_vs[i]) = (f[0], f[1], f[2]);
        (self.a[i], self.b[i], self.c[i]) = (f[5], f[6], f[7]);
        (self.sigma1[i], self.sigma2[i], self.eps[i]) = (f[8], f[9], f[10]);
        let h = m.hysteresis.map_or([0.0; 3], |h| h.constants());
        for k in 0..3 {
            self.hyst[k][i] = h[k];
        }
        self.hysteresis_on[i] = m.hysteresis.is_some();
        self.asymmetric[i] = f[10] != 0.0;
        self.any_hysteresis = self.hysteresis_on.iter().any(|h| *h);
        self.any_asymmetric = self.asymmetric.iter().any(|a| *a);
        (self.kp[i], self.d33[i], self.f_constant[i]) = (m.kp, m.d33, m.f_constant);
        (self.k_ground[i], self.c_weight[i]) = (m.effect_values.k_ground, m.effect_values.c_weight);
        for r in 0..N {
            for c in 0..N {
                self.minv_k[r][c][i] = m.mech.minv_k[r * N + c];
                self.minv_c[r][c][i] = m.mech.minv_c[r * N + c];
            }
            self.minv_main[r][i] = m.mech.minv_main[r];
            self.minv_weight[r][i] = m.mech.minv_weight[r];
        }
    }

    /// dy/dt of every lane at commanded voltage `v_cmd` [V] rising at `dv_cmd` [V/s], the lanes'
    /// states stored lane by lane (`S` an array of 2 N + 3 components, for the compiler to see
    /// the size): transposed to and from [`PlainLanes::rhs_soa`]. Returns each lane's
    /// (Ff [N], dg/dt [m/s]), as `Model::rhs_impl` does.
    #[inline(always)]
    pub fn rhs<E: LaneExp, S: State<Elem = f64>, const D: usize>(
        &self,
        v_cmd: &[f64; L],
        dv_cmd: &[f64; L],
        ys: &[S; L],
        dys: &mut [S; L],
    ) -> ([f64; L], [f64; L]) {
        let y: [[f64; L]; D] = std::array::from_fn(|j| std::array::from_fn(|i| ys[i].as_ref()[j]));
        let mut dy = [[0.0; L]; D];
        let out = self.rhs_soa::<E, D>(v_cmd, dv_cmd, &y, &mut dy);
        for i in 0..L {
            let d = dys[i].as_mut();
            for j in 0..D {
                d[j] = dy[j][i];
            }
        }
        out
    }

    /// [`PlainLanes::rhs`] on states stored component by component: `y[j][i]` is component j
    /// of lane i (the layout the vector instructions want).
    #[inline(always)]
    pub fn rhs_soa<E: LaneExp, const D: usize>(
        &self,
        v_cmd: &[f64; L],
        dv_cmd: &[f64; L],
        y: &[[f64; L]; D],
        dy: &mut [[f64; L]; D],
    ) -> ([f64; L], [f64; L]) {
        let (ig, ifh, ih) = (2 * N, 2 * N + 1, 2 * N + 2);
        let (h, fh) = (&y[ih], &y[ifh]);
        let v0 = &y[N];
        let mut out_h = [0.0; L];
        if self.any_hysteresis {
            let [ap, bp, cp] = &self.hyst;
            for i in 0..L {
                let dv = dv_cmd[i];
                let r = ap[i] * dv - bp[i] * dv.abs() * h[i] - cp[i] * dv * h[i].abs();
                out_h[i] = if self.hysteresis_on[i] { r } else { 0.0 };
            }
        }
        let mut fp = [0.0; L];
        for i in 0..L {
            // piezo_force with xc = 0, in the scalar model's order: kp ((d33 V + 0) - h)
            fp[i] = self.kp[i] * ((self.d33[i] * v_cmd[i] + 0.0) - h[i]);
        }
        // friction: the Stribeck curve, then the Bouc-Wen rates (Leuven::rates, fric_n = 1)
        let mut e = [0.0; L];
        for i in 0..L {
            let x = v0[i].abs() * self.inv_vs[i];
            e[i] = -(x * x);
        }
        // the exps in a loop of their own: a library call per lane then has no vector
        // registers live across it to save (PolyExp vectorises either way)
        for x in e.iter_mut() {
            *x = E::exp(*x);
        }
        let mut s = [0.0; L];
        for i in 0..L {
            let curve = self.fc[i] + self.fs_minus_fc[i] * e[i];
            // a lane without a peak: fc exactly, as the scalar model's shortcut
            s[i] = if self.fs_minus_fc[i] == 0.0 { self.fc[i] } else { curve };
        }
        if self.any_asymmetric {
            for i in 0..L {
                let sg = if v0[i] > 0.0 { 1.0 } else if v0[i] < 0.0 { -1.0 } else { 0.0 };
                let scaled = s[i] * (self.eps[i] * sg + 1.0);
                s[i] = if self.asymmetric[i] { scaled } else { s[i] };
            }
        }
        let (mut gdot, mut ff) = ([0.0; L], [0.0; L]);
        for i in 0..L {
            let ratio = fh[i] / s[i];
            let g = v0[i] - v0[i].abs() * ratio;
            gdot[i] = g;
            dy[ifh][i] = self.a[i] * g - self.b[i] * g.abs() * fh[i] - self.c[i] * g * fh[i].abs();
            ff[i] = (fh[i] + self.sigma2[i] * v0[i]) + self.sigma1[i] * g;
        }
        let (mut f_main, mut f_weight) = ([0.0; L], [0.0; L]);
        for i in 0..L {
            let f_ext_main = self.f_constant[i] + -self.k_ground[i] * y[0][i];
            let f_ext_weight = -self.c_weight[i] * y[2 * N - 1][i];
            f_main[i] = (fp[i] + f_ext_main) - ff[i];
            f_weight[i] = f_ext_weight + -fp[i];
        }
        for r in 0..N {
            for i in 0..L {
                let mut a = 0.0;
                for c in 0..N {
                    a -= self.minv_k[r][c][i] * y[c][i] + self.minv_c[r][c][i] * y[N + c][i];
                }
                dy[N + r][i] = a + self.minv_weight[r][i] * f_weight[i] + self.minv_main[r][i] * f_main[i];
            }
        }
        for j in 0..N {
            dy[j] = y[N + j];
        }
        dy[ig] = gdot;
        dy[ih] = out_h;
        (ff, gdot)
    }
}

/// The driver's right-hand side for a group of plain f64 models: the lanes computed together
/// when [`PlainLanes::new`] accepts the group, else lane by lane through the scalar model
/// (`inner`, which also answers single-lane calls: the implicit method's Jacobian, say). `N`
/// nodes, `D` = 2 N + 3 state components, `L` lanes.
pub struct LanesRhs<'a, E: LaneExp, const N: usize, const D: usize, const L: usize> {
    pub inner: ModelRhs<'a, f64, N, false, L>,
    lanes: Option<PlainLanes<N, L>>,
    _exp: std::marker::PhantomData<E>,
}

impl<'a, E: LaneExp, const N: usize, const D: usize, const L: usize> LanesRhs<'a, E, N, D, L> {
    pub fn new(inner: ModelRhs<'a, f64, N, false, L>) -> Self {
        let lanes = PlainLanes::new(&inner.models);
        LanesRhs { inner, lanes, _exp: std::marker::PhantomData }
    }

    /// Whether the lanes are computed as vectors (else one by one).
    pub fn is_vector(&self) -> bool {
        self.lanes.is_some()
    }
}

impl<E: LaneExp, const N: usize, const D: usize, const L: usize> Rhs<f64> for LanesRhs<'_, E, N, D, L> {
    #[inline(always)]
    fn eval(&mut self, lane: usize, tau: f64, y: &[f64], dy: &mut [f64]) {
        self.inner.eval(lane, tau, y, dy)
    }

    #[inline(always)]
    fn eval_lanes<S: State<Elem = f64>, const M: usize>(
        &mut self,
        tau: &[f64; M],
        ys: &[S; M],
        dys: &mut [S; M],
        active: &[bool; M],
    ) {
        let Some(p) = &self.lanes else {
            for i in 0..M {
                if active[i] {
                    self.inner.eval(i, tau[i], ys[i].as_ref(), dys[i].as_mut());
                }
            }
            return;
        };
        // M is L (the driver's lane count); the generic signature is the trait's
        let (tau, ys, dys, active): (&[f64; L], &[S; L], &mut [S; L], &[bool; L]) = (
            tau.as_slice().try_into().expect("lane count"),
            ys.as_slice().try_into().expect("lane count"),
            dys.as_mut_slice().try_into().expect("lane count"),
            active.as_slice().try_into().expect("lane count"),
        );
        let v_cmd: [f64; L] = std::array::from_fn(|i| self.inner.v0[i] + self.inner.slope[i] * tau[i]);
        let (ff, gdot) = p.rhs::<E, S, D>(&v_cmd, &self.inner.slope, ys, dys);
        for i in 0..L {
            if active[i] && tau[i] == 0.0 {
                self.inner.at_start[i] = (ff[i], gdot[i]);
            }
        }
    }

    #[inline(always)]
    fn admissible(&self, lane: usize, y: &[f64]) -> bool {
        self.inner.admissible(lane, y)
    }

    #[inline(always)]
    fn jacobian(&mut self, lane: usize, tau: f64, y: &[f64], jac: &mut [f64], dfdt: &mut [f64]) {
        self.inner.jacobian(lane, tau, y, jac, dfdt)
    }
}

impl<E: LaneExp, const N: usize, const D: usize, const L: usize> LaneInputs<f64, L> for LanesRhs<'_, E, N, D, L> {
    #[inline(always)]
    fn set_input(&mut self, i: usize, t0: f64, v0: f64, slope: f64) {
        self.inner.set_input(i, t0, v0, slope)
    }
    #[inline(always)]
    fn input(&self, i: usize) -> (f64, f64) {
        self.inner.input(i)
    }
    #[inline(always)]
    fn at_start(&self, i: usize) -> (f64, f64) {
        self.inner.at_start(i)
    }
}

/// 0: AVX2 where the processor has it; 1: scalar code; 3: AVX-512 where it has it (for tests
/// and benchmarks: the results are bitwise the same, only the speed differs).
static DISPATCH: std::sync::atomic::AtomicU8 = std::sync::atomic::AtomicU8::new(0);

/// Choose the lane groups' instruction set: "scalar", "avx2" (the default) or "avx512" (each
/// falling back to the best the processor has below it). Results are bitwise the same.
pub fn set_simd_level(level: &str) {
    let code = match level {
        "scalar" => 1,
        "avx512" => 3,
        _ => 0,
    };
    DISPATCH.store(code, std::sync::atomic::Ordering::Relaxed);
}

/// The instruction set the lane groups run on, detected at run time by `pulp` (one wheel
/// serves every x86-64 machine): AVX2 (+FMA) where the processor has it, else scalar. AVX-512
/// only when asked for: on the machine measured (benches/RESULTS.md) its 8-lane code ran the
/// model's right-hand side slower than AVX2's, whose per-lane dependency chains overlap better.
pub fn simd_arch() -> pulp::Arch {
    match DISPATCH.load(std::sync::atomic::Ordering::Relaxed) {
        1 => pulp::Arch::Scalar,
        3 => pulp::Arch::new(),
        #[cfg(target_arch = "x86_64")]
        _ => pulp::x86::V3::try_new().map_or(pulp::Arch::Scalar, pulp::Arch::V3),
        #[cfg(not(target_arch = "x86_64"))]
        _ => pulp::Arch::new(),
    }
}

/// The instruction set `simd_arch` picks, in words ("avx512", "avx2" or "scalar").
pub fn simd_level() -> &'static str {
    match simd_arch() {
        #[cfg(target_arch = "x86_64")]
        pulp::Arch::V4(_) => "avx512",
        #[cfg(target_arch = "x86_64")]
        pulp::Arch::V3(_) => "avx2",
        _ => "scalar",
    }
}

/// How often (in attempts) a lane driver looks at the cancel flag.
const CANCEL_CHECK_ATTEMPTS: usize = 1 << 12;

/// What a lane driver does next (see [`refill_lanes`]).
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) enum Queue {
    /// attempt a step on the lanes that hold a task
    Go,
    /// every task has ended
    Done,
    /// the cancel flag is set
    Cancelled,
}

/// The queue step every SoA lane driver (`lanes_rk4.rs`, `lanes_dopri5.rs`) takes before an
/// attempt: each empty lane gets the next task of `tasks` (its model into `p`, its initial state
/// into `y`, the observer told it starts; `slot(lane, task)` builds what the driver keeps of it).
/// Every [`CANCEL_CHECK_ATTEMPTS`] attempts it also looks at `cancel`.
#[allow(clippy::too_many_arguments)]
#[inline(always)]
pub(crate) fn refill_lanes<Sl, O: Observer, const N: usize, const D: usize, const L: usize>(
    tasks: &[Task],
    next: &mut usize,
    slots: &mut [Option<Sl>; L],
    p: &mut PlainLanes<N, L>,
    y: &mut [[f64; L]; D],
    observer: &mut O,
    attempts: &mut usize,
    cancel: &AtomicBool,
    mut slot: impl FnMut(usize, usize) -> Sl,
) -> Queue {
    for i in 0..L {
        if slots[i].is_none() && *next < tasks.len() {
            let task = &tasks[*next];
            p.set(i, task.model);
            for j in 0..D {
                y[j][i] = task.y0[j];
            }
            slots[i] = Some(slot(i, *next));
            observer.start(*next, task.t_start, task.y0);
            *next += 1;
        }
    }
    if slots.iter().all(|s| s.is_none()) {
        return Queue::Done;
    }
    if *attempts % CANCEL_CHECK_ATTEMPTS == 0 && cancel.load(Ordering::Relaxed) {
        return Queue::Cancelled;
    }
    *attempts += 1;
    Queue::Go
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::drive::{run_tasks, run_tasks_one_by_one, LaneEnd, Method, Observer, Task};
    use crate::effects::Effects;
    use crate::mechanics::Structure;
    use crate::params::Params;
    use crate::waveform::PiecewiseLinear;
    use std::sync::atomic::AtomicBool;

    struct Nothing;
    impl Observer for Nothing {
        fn start(&mut self, _: usize, _: f64, _: &[f64]) {}
        fn step(&mut self, _: usize, _: f64, _: f64, _: &[f64], _: f64, _: Option<(f64, f64)>, _: bool) {}
    }

    /// Eleven devices that differ in every constant the vector path reads, with hysteresis on
    /// some and effects that add no state on others.
    fn models(structure: Structure) -> Vec<Model> {
        (0..11)
            .map(|k| {
                let f = 1.0 + 0.07 * k as f64;
                let mut p = Params::paper();
                p.m2 *= f;
                p.mu_k *= 1.0 / f.sqrt();
                p.sigma1 *= f;
                p.fric_alpha *= f;
                p.d33 *= 2.0 - f.sqrt();
                if k == 3 {
                    p.mu_s = p.mu_k; // no Stribeck peak
                }
                let mut e = Effects::default();
                if k % 4 == 1 {
                    e.k_ground = 300.0 * k as f64;
                    e.c_weight = 0.1;
                }
                if k % 5 == 2 {
                    e.eps = 0.05;
                }
                Model::new(p, e, structure, k % 3 == 0, false).unwrap()
            })
            .collect()
    }

    fn run(models: &[Model], wave: &PiecewiseLinear, lanes8: bool) -> Vec<Vec<f64>> {
        run_with(models, wave, lanes8, &Method::Rk4 { dt: 5e-8 })
    }

    fn run_with(models: &[Model], wave: &PiecewiseLinear, lanes8: bool, method: &Method) -> Vec<Vec<f64>> {
        let y0: Vec<Vec<f64>> = models.iter().map(|m| m.rest_state()).collect();
        let tasks: Vec<Task> = models
            .iter()
            .zip(&y0)
            .map(|(m, y)| Task { model: m, wave, t_start: 0.0, t_end: 2e-3, y0: y })
            .collect();
        let cancel = AtomicBool::new(false);
        let ends = if lanes8 {
            run_tasks::<_, 8>(&tasks, method, &mut Nothing, &cancel)
        } else {
            run_tasks_one_by_one(&tasks, method, &Default::default(), &mut Nothing, &cancel)
        };
        ends.unwrap().into_iter().map(|(_, y)| y).collect()
    }

    #[test]
    fn vector_lanes_are_bitwise_the_scalar_model_with_and_without_simd() {
        let wave = PiecewiseLinear::triangle(80.0, 0.5e-3, 1.0e-3, 0.0).unwrap();
        for structure in [Structure::Lps, Structure::Dps(4)] {
            let ms = models(structure);
            let n = ms[0].layout.dof;
            let group: [&Model; 8] = std::array::from_fn(|i| &ms[i]);
            assert!(PlainLanes::<2, 8>::new(&group).is_some() || n != 2);
            let reference = run(&ms, &wave, false);
            set_simd_level("scalar");
            let scalar = run(&ms, &wave, true);
            set_simd_level("avx2");
            let vector = run(&ms, &wave, true);
            assert_eq!(scalar, reference, "{structure:?}: forced-scalar lanes differ from the model");
            assert_eq!(vector, reference, "{structure:?}: {} lanes differ from the model", simd_level());
            let x: Vec<f64> = reference.iter().map(|y| y[0]).collect();
            assert!(x.iter().all(|x| x.abs() > 1e-8), "every device moved: {x:?}");
        }
    }

    #[test]
    fn dopri5_stages_on_vector_lanes_are_bitwise_the_scalar_model() {
        // per-lane steps: the lanes' stages sit at different offsets within their steps
        let wave = PiecewiseLinear::triangle(80.0, 0.5e-3, 1.0e-3, 0.0).unwrap();
        let method = Method::Dopri5 { rtol: 1e-7, atol: 1e-7, first_step: 1e-8 };
        for structure in [Structure::Lps, Structure::Dps(4)] {
            let ms = models(structure);
            let reference = run_with(&ms, &wave, false, &method);
            for level in ["scalar", "avx2", "avx512"] {
                set_simd_level(level);
                assert_eq!(run_with(&ms, &wave, true, &method), reference, "{structure:?} {level}");
            }
            set_simd_level("avx2");
        }
    }

    /// The accepted steps after which each run changed method (to Rodas4, back, ...).
    #[derive(Default)]
    struct Switches(std::collections::BTreeMap<usize, Vec<u64>>);
    impl Observer for Switches {
        fn start(&mut self, _: usize, _: f64, _: &[f64]) {}
        fn step(&mut self, _: usize, _: f64, _: f64, _: &[f64], _: f64, _: Option<(f64, f64)>, _: bool) {}
        fn switched(&mut self, task: usize, accepted: u64) {
            self.0.entry(task).or_default().push(accepted);
        }
    }

    #[test]
    fn auto_on_vector_lanes_hands_stiff_runs_over_bitwise_as_the_scalar_path() {
        // the eleven devices, and three whose friction state is far stiffer (a presliding
        // stiffness 1,000x the paper's, a near-frictionless contact): those switch to Rodas4
        let wave = PiecewiseLinear::triangle(80.0, 0.5e-3, 1.0e-3, 0.0).unwrap();
        let method = Method::Auto { rtol: 3e-7, atol: 3e-7, first_step: 1e-8 };
        for structure in [Structure::Lps, Structure::Dps(4)] {
            let mut ms = models(structure);
            for (alpha, mu) in [(1e3, 1.0), (3e3, 1.0), (1.0, 1e-5)] {
                let mut p = Params::paper();
                p.fric_alpha *= alpha;
                p.mu_k *= mu;
                p.mu_s *= mu;
                ms.insert(4, Model::new(p, Effects::default(), structure, false, false).unwrap());
            }
            let y0: Vec<Vec<f64>> = ms.iter().map(|m| m.rest_state()).collect();
            let tasks: Vec<Task> = ms
                .iter()
                .zip(&y0)
                .map(|(m, y)| Task { model: m, wave: &wave, t_start: 0.0, t_end: 2e-3, y0: y })
                .collect();
            let cancel = AtomicBool::new(false);
            let mut seen = Switches::default();
            let reference = run_tasks_one_by_one(&tasks, &method, &Default::default(), &mut seen, &cancel).unwrap();
            // the three stiff devices (inserted at 4: tasks 4-6) change to Rodas4 early
            for i in 4..7 {
                let at = &seen.0[&i];
                // after TRY_IMPLICIT_AFTER steps at the stability limit (and the run's first,
                // non-stiff steps): measured 467-545
                assert!(at[0] < 3 * crate::stiffness::TRY_IMPLICIT_AFTER as u64, "{structure:?} task {i}: switches {at:?}");
            }
            for level in ["scalar", "avx2"] {
                set_simd_level(level);
                let mut lanes = Switches::default();
                let ends = run_tasks::<_, 8>(&tasks, &method, &mut lanes, &cancel).unwrap();
                assert_eq!(ends, reference, "{structure:?} {level}");
                assert_eq!(lanes.0, seen.0, "{structure:?} {level}: the same runs switch at the same step");
            }
            set_simd_level("avx2");
        }
    }

    #[test]
    fn a_crawling_lane_stops_as_on_the_scalar_path_and_its_neighbours_finish() {
        // a near-frictionless contact (mu 1e-6) holds Dormand-Prince at its stability limit
        let wave = PiecewiseLinear::triangle(50.0, 0.5e-3, 0.5e-3, 0.0).unwrap();
        let method = Method::Dopri5 { rtol: 3e-7, atol: 3e-7, first_step: 1e-8 };
        let mut ms = models(Structure::Lps);
        let mut p = Params::paper();
        p.mu_k = 1e-6;
        p.mu_s = 1e-6;
        ms.insert(2, Model::new(p, Effects::default(), Structure::Lps, false, false).unwrap());
        let y0: Vec<Vec<f64>> = ms.iter().map(|m| m.rest_state()).collect();
        let tasks: Vec<Task> = ms
            .iter()
            .zip(&y0)
            .map(|(m, y)| Task { model: m, wave: &wave, t_start: 0.0, t_end: 1e-3, y0: y })
            .collect();
        let cancel = AtomicBool::new(false);
        let reference = run_tasks_one_by_one(&tasks, &method, &Default::default(), &mut Nothing, &cancel).unwrap();
        for (i, (end, _)) in reference.iter().enumerate() {
            match end {
                LaneEnd::Diverged { why: Some(why), .. } if i == 2 => {
                    assert!(why.starts_with(crate::crawl::CRAWL_PREFIX), "{why}")
                }
                LaneEnd::Finished { .. } if i != 2 => {}
                other => panic!("task {i}: {other:?}"),
            }
        }
        for level in ["scalar", "avx2"] {
            set_simd_level(level);
            let ends = run_tasks::<_, 8>(&tasks, &method, &mut Nothing, &cancel).unwrap();
            assert_eq!(ends, reference, "{level}");
        }
        set_simd_level("avx2");
    }

    #[test]
    fn groups_the_vector_path_cannot_compute_exactly_run_lane_by_lane() {
        let mut p = Params::paper();
        p.stribeck_exponent = 1.5;
        let odd = Model::new(p, Effects::default(), Structure::Lps, false, false).unwrap();
        let plain = Model::new(Params::paper(), Effects::default(), Structure::Lps, false, false).unwrap();
        assert!(PlainLanes::<2, 2>::new(&[&plain, &plain]).is_some());
        assert!(PlainLanes::<2, 2>::new(&[&plain, &odd]).is_none());
        let ms = vec![plain.clone(), odd.clone(), plain, odd];
        let wave = PiecewiseLinear::triangle(80.0, 0.5e-3, 1.0e-3, 0.0).unwrap();
        assert_eq!(run(&ms, &wave, true), run(&ms, &wave, false));
    }
}
