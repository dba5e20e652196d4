//! `L` plain models at once: one [`Model`] over [`Lanes`] (`numbers/lane_real.rs`), whose right-hand
//! side is the scalar model's own code (`Model::rhs_impl`) with every number a vector of lanes,
//! so a lane's result is bitwise the scalar model's (with [`LibmExp`]; [`PolyExp`] within 2 ulp
//! per exp). The lane drivers (`lanes/rk4.rs`, `lanes/dopri5.rs`) keep the state component by
//! component (`y[j][i]`: component j of lane i), the layout the vector instructions want, and
//! run under `pulp`'s runtime dispatch (`drive.rs`).
//!
//! Which models run on lanes is [`PlainLanes::accepts`]: a state the drivers' fixed-size state
//! holds (nodes, g, Fh, h and the lag effects' states, no accounting: [`Model::lane_lags`]) and
//! no sampled external force (the lane drivers do not end steps at its knots); the models of
//! one group share a [`Shape`](crate::model::Shape). Anything else runs lane by lane through
//! the scalar model.

pub mod dopri5;
pub mod rk4;

use std::sync::atomic::{AtomicBool, Ordering};

use crate::integrate::model_rhs::{LaneInputs, ModelRhs};
use crate::integrate::stepper::{Rhs, State};
use crate::integrate::task::{Observer, Task};
use crate::model::Model;
use crate::numbers::lane_real::Lanewise;
pub use crate::numbers::lane_real::{LaneExp, Lanes, LibmExp, PolyExp};

/// `L` plain models of one shape with `N` nodes as one model over lanes.
#[derive(Clone, Debug)]
pub struct PlainLanes<const N: usize, const L: usize, E: LaneExp = LibmExp> {
    model: Model<Lanes<L, E>>,
}

impl<const N: usize, const L: usize, E: LaneExp> PlainLanes<N, L, E> {
    /// Whether the lane drivers run `m`: `N` nodes, no accounting states (the lag effects'
    /// states are held), no sampled external force.
    pub fn accepts(m: &Model) -> bool {
        m.lane_lags().is_some() && m.external.is_none() && m.layout.dof == N
    }

    /// The lanes of `models`, or `None` when one is not accepted or the shapes differ.
    pub fn new(models: &[&Model; L]) -> Option<Self> {
        let shape = models[0].shape();
        if !models.iter().all(|m| Self::accepts(m) && m.shape() == shape) {
            return None;
        }
        let mut p = PlainLanes {
            model: Lanewise::splat(models[0]),
        };
        for (i, m) in models.iter().enumerate().skip(1) {
            p.set(i, m);
        }
        Some(p)
    }

    /// Whether `m` can join these lanes (accepted, and of their shape).
    pub fn admits(&self, m: &Model) -> bool {
        Self::accepts(m) && m.shape() == self.model.shape()
    }

    /// Put model `m` (which [`PlainLanes::admits`]) on lane `i`.
    #[inline(always)]
    pub fn set(&mut self, i: usize, m: &Model) {
        debug_assert!(self.admits(m));
        self.model.set_lane(i, m);
    }

    /// dy/dt of every lane at times `t` [s], commanded voltage `v_cmd` [V] rising at `dv_cmd`
    /// [V/s], the lanes' states stored lane by lane (`S` an array of the D = 2 N + 3 components
    /// of a plain state): transposed to and from [`PlainLanes::rhs_soa`]. Returns each lane's
    /// (Ff [N], dg/dt [m/s]), as `Model::rhs_impl` does.
    #[inline(always)]
    pub fn rhs<S: State<Elem = f64>, const D: usize>(
        &self,
        t: &[f64; L],
        v_cmd: &[f64; L],
        dv_cmd: &[f64; L],
        ys: &[S; L],
        dys: &mut [S; L],
    ) -> ([f64; L], [f64; L]) {
        let y: [[f64; L]; D] = std::array::from_fn(|j| std::array::from_fn(|i| ys[i].as_ref()[j]));
        let mut dy = [[0.0; L]; D];
        let out = self.rhs_soa::<D, false>(t, v_cmd, dv_cmd, &y, &mut dy);
        for i in 0..L {
            let d = dys[i].as_mut();
            for j in 0..D {
                d[j] = dy[j][i];
            }
        }
        out
    }

    /// [`PlainLanes::rhs`] on states stored component by component: `y[j][i]` is component j
    /// of lane i, D = 2 N + 3 + the lag states, `EXTRAS` whether there are lag states. The
    /// model's own right-hand side, over lanes.
    #[inline(always)]
    pub fn rhs_soa<const D: usize, const EXTRAS: bool>(
        &self,
        t: &[f64; L],
        v_cmd: &[f64; L],
        dv_cmd: &[f64; L],
        y: &[[f64; L]; D],
        dy: &mut [[f64; L]; D],
    ) -> ([f64; L], [f64; L]) {
        // rhs_impl writes every one of the D components (no accounting states on lanes)
        debug_assert_eq!(D, self.model.layout.dim);
        let (ff, gdot) = self.model.rhs_impl::<N, EXTRAS>(
            Lanes::new(*t),
            Lanes::new(*v_cmd),
            Lanes::new(*dv_cmd),
            Lanes::view(y),
            Lanes::view_mut(dy),
        );
        (ff.0, gdot.0)
    }
}

/// The driver's right-hand side for a group of plain f64 models: the lanes computed together
/// when [`PlainLanes::new`] accepts the group, else lane by lane through the scalar model
/// (`inner`, which also answers single-lane calls: the implicit method's Jacobian, say). `N`
/// nodes, `D` = 2 N + 3 state components, `L` lanes; `EXTRAS`: the states may hold lag states
/// (`inner`'s layout), which run lane by lane.
pub struct LanesRhs<'a, E: LaneExp, const N: usize, const D: usize, const L: usize, const EXTRAS: bool = false> {
    pub inner: ModelRhs<'a, f64, N, EXTRAS, L>,
    lanes: Option<PlainLanes<N, L, E>>,
    _exp: std::marker::PhantomData<E>,
}

impl<'a, E: LaneExp, const N: usize, const D: usize, const L: usize, const EXTRAS: bool>
    LanesRhs<'a, E, N, D, L, EXTRAS>
{
    pub fn new(inner: ModelRhs<'a, f64, N, EXTRAS, L>) -> Self {
        // `PlainLanes::rhs` takes the state as plain (no lag states)
        let lanes = PlainLanes::new(&inner.models).filter(|_| !EXTRAS && inner.models.iter().all(|m| m.is_plain()));
        LanesRhs {
            inner,
            lanes,
            _exp: std::marker::PhantomData,
        }
    }

    /// [`LanesRhs::new`] over [`ModelRhs::for_tasks`].
    pub fn for_tasks(tasks: &[Task<'a>], slack: f64) -> Self {
        Self::new(ModelRhs::for_tasks(tasks, slack))
    }

    /// Whether the lanes are computed as vectors (else one by one).
    pub fn is_vector(&self) -> bool {
        self.lanes.is_some()
    }
}

impl<E: LaneExp, const N: usize, const D: usize, const L: usize, const EXTRAS: bool> Rhs<f64>
    for LanesRhs<'_, E, N, D, L, EXTRAS>
{
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
        // a vector step costs what L/2 to L/3 lanes cost one by one, busy or not
        // (`drive::run_fixed`): fewer busy lanes than half go one by one (the same bits)
        let busy = active.iter().filter(|a| **a).count();
        let Some(p) = self.lanes.as_ref().filter(|_| 2 * busy >= L) else {
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
        let t: [f64; L] = std::array::from_fn(|i| self.inner.t0[i] + tau[i]);
        let v_cmd: [f64; L] = std::array::from_fn(|i| self.inner.v0[i] + self.inner.slope[i] * tau[i]);
        let (ff, gdot) = p.rhs::<S, D>(&t, &v_cmd, &self.inner.slope, ys, dys);
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

impl<E: LaneExp, const N: usize, const D: usize, const L: usize, const EXTRAS: bool> LaneInputs<f64, L>
    for LanesRhs<'_, E, N, D, L, EXTRAS>
{
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

/// The queue step every SoA lane driver (`lanes/rk4.rs`, `lanes/dopri5.rs`) takes before an
/// attempt: each empty lane gets the next task of `tasks` (its model into `p`, its initial state
/// into `y`, the observer told it starts; `slot(lane, task)` builds what the driver keeps of it).
/// Every [`CANCEL_CHECK_ATTEMPTS`] attempts it also looks at `cancel`.
#[allow(clippy::too_many_arguments)]
// a lane's column of the component-major state is written by component index, beside y0
#[allow(clippy::needless_range_loop)]
#[inline(always)]
pub(crate) fn refill_lanes<Sl, O: Observer, E: LaneExp, const N: usize, const D: usize, const L: usize>(
    tasks: &[Task],
    next: &mut usize,
    slots: &mut [Option<Sl>; L],
    p: &mut PlainLanes<N, L, E>,
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
    if (*attempts).is_multiple_of(CANCEL_CHECK_ATTEMPTS) && cancel.load(Ordering::Relaxed) {
        return Queue::Cancelled;
    }
    *attempts += 1;
    Queue::Go
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::drive::{run_tasks, run_tasks_one_by_one};
    use crate::integrate::method::Method;
    use crate::integrate::task::{LaneEnd, Observer, Task};
    use crate::physics::effects::Effects;
    use crate::physics::mechanics::Structure;
    use crate::physics::params::Params;
    use crate::physics::waveform::PiecewiseLinear;
    use std::sync::atomic::AtomicBool;

    struct Nothing;
    impl Observer for Nothing {
        fn start(&mut self, _: usize, _: f64, _: &[f64]) {}
        fn step(&mut self, _: usize, _: f64, _: f64, _: &[f64], _: f64, _: Option<(f64, f64)>, _: bool) {}
    }

    /// Eleven devices that differ in every constant the physics reads — Stribeck peak or none,
    /// Stribeck exponent, Bouc-Wen exponent, direction asymmetry, effects that add no state —
    /// of one shape (piezo hysteresis off; see `models_with`).
    fn models(structure: Structure) -> Vec<Model> {
        models_with(structure, false)
    }

    fn models_with(structure: Structure, hysteresis: bool) -> Vec<Model> {
        (0..11)
            .map(|k| {
                let f = 1.0 + 0.07 * k as f64;
                let mut p = Params::paper();
                p.m2 *= f;
                p.mu_k *= 1.0 / f.sqrt();
                p.sigma1 *= f;
                p.fric_alpha *= f;
                p.d33 *= 2.0 - f.sqrt();
                p.hyst_alpha *= f;
                if k == 3 {
                    p.mu_s = p.mu_k; // no Stribeck peak
                }
                if k == 6 {
                    p.stribeck_exponent = 1.5; // a power per lane, not the square
                }
                if k == 8 {
                    p.fric_n = 1.3;
                }
                let mut e = Effects::default();
                if k % 4 == 1 {
                    e.k_ground = 300.0 * k as f64;
                    e.c_weight = 0.1;
                }
                if k % 5 == 2 {
                    e.eps = 0.05;
                }
                Model::new(p, e, structure, hysteresis, false).unwrap()
            })
            .collect()
    }

    fn run(models: &[Model], wave: &PiecewiseLinear, lanes8: bool) -> Vec<Vec<f64>> {
        run_with(models, wave, lanes8, &Method::Rk4 { dt: 5e-8 })
    }

    fn run_with(models: &[Model], wave: &PiecewiseLinear, lanes8: bool, method: &Method) -> Vec<Vec<f64>> {
        run_for(models, wave, lanes8, method, 2e-3)
    }

    fn run_for(models: &[Model], wave: &PiecewiseLinear, lanes8: bool, method: &Method, t_end: f64) -> Vec<Vec<f64>> {
        let y0: Vec<Vec<f64>> = models.iter().map(|m| m.rest_state()).collect();
        let tasks: Vec<Task> = models
            .iter()
            .zip(&y0)
            .map(|(m, y)| Task {
                model: m,
                wave,
                t_start: 0.0,
                t_end,
                y0: y,
            })
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
        for (structure, hysteresis) in [
            (Structure::Lps, false),
            (Structure::Lps, true),
            (Structure::Dps(4), true),
        ] {
            let ms = models_with(structure, hysteresis);
            let n = ms[0].layout.dof;
            let group: [&Model; 8] = std::array::from_fn(|i| &ms[i]);
            assert!(PlainLanes::<2, 8>::new(&group).is_some() || n != 2);
            let reference = run(&ms, &wave, false);
            set_simd_level("scalar");
            let scalar = run(&ms, &wave, true);
            set_simd_level("avx2");
            let vector = run(&ms, &wave, true);
            assert_eq!(
                scalar, reference,
                "{structure:?}: forced-scalar lanes differ from the model"
            );
            assert_eq!(
                vector,
                reference,
                "{structure:?}: {} lanes differ from the model",
                simd_level()
            );
            let x: Vec<f64> = reference.iter().map(|y| y[0]).collect();
            assert!(x.iter().all(|x| x.abs() > 1e-8), "every device moved: {x:?}");
        }
    }

    #[test]
    fn dopri5_stages_on_vector_lanes_are_bitwise_the_scalar_model() {
        // per-lane steps: the lanes' stages sit at different offsets within their steps
        let wave = PiecewiseLinear::triangle(80.0, 0.5e-3, 1.0e-3, 0.0).unwrap();
        let method = Method::Dopri5 {
            rtol: 1e-7,
            atol: 1e-7,
            first_step: 1e-8,
        };
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

    #[test]
    fn rodas4_on_lanes_is_bitwise_rodas4_alone() {
        // per-lane pivots, steps and rejections; the stages' right-hand side as vectors where half
        // the lanes are busy (the eleven devices: one full group of 8, one of 3, lane by lane)
        let wave = PiecewiseLinear::triangle(80.0, 0.5e-3, 1.0e-3, 0.0).unwrap();
        let method = Method::Rodas4 {
            rtol: 1e-6,
            atol: 1e-6,
            first_step: 1e-8,
        };
        for structure in [Structure::Lps, Structure::Dps(4)] {
            let ms = models(structure);
            let reference = run_with(&ms, &wave, false, &method);
            assert!(reference.iter().all(|y| y[0].abs() > 1e-8), "every device moved");
            for level in ["scalar", "avx2"] {
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
        let method = Method::Auto {
            rtol: 3e-7,
            atol: 3e-7,
            first_step: 1e-8,
        };
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
                .map(|(m, y)| Task {
                    model: m,
                    wave: &wave,
                    t_start: 0.0,
                    t_end: 2e-3,
                    y0: y,
                })
                .collect();
            let cancel = AtomicBool::new(false);
            let mut seen = Switches::default();
            let reference = run_tasks_one_by_one(&tasks, &method, &Default::default(), &mut seen, &cancel).unwrap();
            // the three stiff devices (inserted at 4: tasks 4-6) change to Rodas4 early
            for i in 4..7 {
                let at = &seen.0[&i];
                // after TRY_IMPLICIT_AFTER steps at the stability limit (and the run's first,
                // non-stiff steps): measured 467-545
                assert!(
                    at[0] < 3 * crate::integrate::stiffness::TRY_IMPLICIT_AFTER as u64,
                    "{structure:?} task {i}: switches {at:?}"
                );
            }
            for level in ["scalar", "avx2"] {
                set_simd_level(level);
                let mut lanes = Switches::default();
                let ends = run_tasks::<_, 8>(&tasks, &method, &mut lanes, &cancel).unwrap();
                assert_eq!(ends, reference, "{structure:?} {level}");
                assert_eq!(
                    lanes.0, seen.0,
                    "{structure:?} {level}: the same runs switch at the same step"
                );
            }
            set_simd_level("avx2");
        }
    }

    #[test]
    fn a_crawling_lane_stops_as_on_the_scalar_path_and_its_neighbours_finish() {
        // a near-frictionless contact (mu 1e-6) holds Dormand-Prince at its stability limit
        let wave = PiecewiseLinear::triangle(50.0, 0.5e-3, 0.5e-3, 0.0).unwrap();
        let method = Method::Dopri5 {
            rtol: 3e-7,
            atol: 3e-7,
            first_step: 1e-8,
        };
        let mut ms = models(Structure::Lps);
        let mut p = Params::paper();
        p.mu_k = 1e-6;
        p.mu_s = 1e-6;
        ms.insert(
            2,
            Model::new(p, Effects::default(), Structure::Lps, false, false).unwrap(),
        );
        let y0: Vec<Vec<f64>> = ms.iter().map(|m| m.rest_state()).collect();
        // the crawling lane runs to 10 ms: its projected count passes the limit within a few
        // checks (at 1 ms it hovered at the limit for 557,056 steps: most of this test's CI time)
        let tasks: Vec<Task> = ms
            .iter()
            .zip(&y0)
            .enumerate()
            .map(|(i, (m, y))| Task {
                model: m,
                wave: &wave,
                t_start: 0.0,
                t_end: if i == 2 { 1e-2 } else { 1e-3 },
                y0: y,
            })
            .collect();
        let cancel = AtomicBool::new(false);
        let reference = run_tasks_one_by_one(&tasks, &method, &Default::default(), &mut Nothing, &cancel).unwrap();
        for (i, (end, _)) in reference.iter().enumerate() {
            match end {
                LaneEnd::Diverged { why: Some(why), .. } if i == 2 => {
                    assert!(why.starts_with(crate::integrate::crawl::CRAWL_PREFIX), "{why}");
                    let steps: u64 = why
                        .split(" steps so far")
                        .next()
                        .and_then(|x| x.rsplit(' ').next())
                        .unwrap()
                        .parse()
                        .unwrap();
                    assert!(
                        steps <= 10 * crate::integrate::crawl::CRAWL_CHECK_STEPS,
                        "caught within a few checks: {why}"
                    );
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
    fn models_of_another_shape_run_lane_by_lane() {
        // hysteresis on and off are two shapes (a state the other lacks the physics of); a
        // Stribeck exponent other than 2 is only a value
        let mut p = Params::paper();
        p.stribeck_exponent = 1.5;
        let odd = Model::new(p, Effects::default(), Structure::Lps, false, false).unwrap();
        let plain = Model::new(Params::paper(), Effects::default(), Structure::Lps, false, false).unwrap();
        let hyst = Model::new(Params::paper(), Effects::default(), Structure::Lps, true, false).unwrap();
        assert!(PlainLanes::<2, 2>::new(&[&plain, &odd]).is_some());
        assert!(PlainLanes::<2, 2>::new(&[&plain, &hyst]).is_none());
        let e = Effects {
            tau_sensor: 1e-5,
            ..Effects::default()
        }; // a lag: another state layout, on lanes
        let lagged = Model::new(Params::paper(), e, Structure::Lps, false, false).unwrap();
        assert!(PlainLanes::<2, 2>::accepts(&lagged));
        assert!(PlainLanes::<2, 2>::new(&[&plain, &lagged]).is_none());
        // accounting states are not held by the lane drivers
        let counted = Model::new(Params::paper(), Effects::default(), Structure::Lps, false, true).unwrap();
        assert!(!PlainLanes::<2, 2>::accepts(&counted));
        let ms = vec![plain.clone(), hyst.clone(), odd, hyst, plain, lagged];
        let wave = PiecewiseLinear::triangle(80.0, 0.5e-3, 1.0e-3, 0.0).unwrap();
        assert_eq!(run(&ms, &wave, true), run(&ms, &wave, false));
    }

    #[test]
    fn lag_states_on_vector_lanes_are_bitwise_the_scalar_model() {
        // each lag effect (one extra state) on the eleven devices, its time constant per lane;
        // RK4 and auto (Dormand-Prince, whose stiff lanes hand over to Rodas4); every lag on
        // the LPS, the sensor's on the DPS4 (1 ms: the unoptimised CI build runs it)
        let wave = PiecewiseLinear::triangle(80.0, 0.5e-3, 1.0e-3, 0.0).unwrap();
        let methods = [
            Method::Rk4 { dt: 5e-8 },
            Method::Auto {
                rtol: 3e-7,
                atol: 3e-7,
                first_step: 1e-8,
            },
        ];
        let cases = [
            (Structure::Lps, "tau_amp"),
            (Structure::Lps, "tau_creep"),
            (Structure::Lps, "tau_sensor"),
            (Structure::Dps(4), "tau_sensor"),
        ];
        for (structure, lag) in cases {
            let ms: Vec<Model> = models(structure)
                .into_iter()
                .enumerate()
                .map(|(k, m)| {
                    let mut e = m.effects;
                    let tau = 2e-6 * (1.0 + 0.3 * k as f64);
                    match lag {
                        "tau_amp" => e.tau_amp = tau,
                        "tau_creep" => (e.kappa, e.tau_creep) = (0.02 * (1.0 + 0.1 * k as f64), 100.0 * tau),
                        _ => e.tau_sensor = tau,
                    }
                    Model::new(m.params, e, structure, false, false).unwrap()
                })
                .collect();
            assert_eq!(ms[0].lane_lags(), Some(1), "{lag}");
            let group: [&Model; 8] = std::array::from_fn(|i| &ms[i]);
            assert!(PlainLanes::<2, 8>::new(&group).is_some() || structure != Structure::Lps);
            for method in &methods {
                let reference = run_for(&ms, &wave, false, method, 1e-3);
                assert!(
                    reference
                        .iter()
                        .all(|y| y.len() == ms[0].layout.dim && y[0].abs() > 1e-8),
                    "{lag}: moved"
                );
                for level in ["scalar", "avx2"] {
                    set_simd_level(level);
                    assert_eq!(
                        run_for(&ms, &wave, true, method, 1e-3),
                        reference,
                        "{structure:?} {lag} {method:?} {level}"
                    );
                }
                set_simd_level("avx2");
            }
        }
    }

    #[test]
    fn library_forces_on_vector_lanes_are_bitwise_the_scalar_model() {
        // every library term, with time and position in it: each lane reads its own clock
        let wave = PiecewiseLinear::triangle(80.0, 0.5e-3, 1.0e-3, 0.0).unwrap();
        let ms: Vec<Model> = models(Structure::Lps)
            .into_iter()
            .enumerate()
            .map(|(k, m)| {
                let mut e = m.effects;
                let f = 1.0 + 0.1 * k as f64;
                (e.lib_x1sq, e.lib_sin, e.lib_wavelength, e.lib_ff_cos) = (1e6 * f, 0.05 * f, 20e-6 * f, 0.02);
                (e.lib_t, e.lib_abs, e.libw_sgn, e.libw_vv) = (0.5 * f, 0.3, 0.01 * f, 2.0);
                if k == 4 {
                    e.lib_wavelength = 0.0; // no periodic term in this lane
                }
                Model::new(m.params, e, Structure::Lps, false, false).unwrap()
            })
            .collect();
        let group: [&Model; 8] = std::array::from_fn(|i| &ms[i]);
        assert!(PlainLanes::<2, 8>::new(&group).is_some());
        let reference = run(&ms, &wave, false);
        for level in ["scalar", "avx2"] {
            set_simd_level(level);
            assert_eq!(run(&ms, &wave, true), reference, "{level}");
        }
        set_simd_level("avx2");
        let plain = run(&models(Structure::Lps), &wave, false);
        assert!(
            reference.iter().zip(&plain).all(|(a, b)| a[0] != b[0]),
            "the library forces act"
        );
    }
}
