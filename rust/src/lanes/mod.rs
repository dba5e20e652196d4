//! `L` plain models at once: one [`Model`] over [`Lanes`] (`numbers/lane_real.rs`), whose right-hand
//! side is the scalar model's own code (`Model::rhs_impl`) with every number a vector of lanes,
//! so a lane's result is bitwise the scalar model's (with [`LibmExp`]; [`PolyExp`] within 2 ulp
//! per exp). The lane drivers (`lanes/rk4.rs`, `lanes/dopri5.rs`) keep the state component by
//! component (`y[j][i]`: component j of lane i), the layout the vector instructions want, and
//! run under `pulp`'s runtime dispatch (`drive/`).
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
mod tests;
