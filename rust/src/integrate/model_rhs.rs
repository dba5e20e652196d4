//! The model as the steppers' right-hand side over a group of `L` lanes: each lane's input over
//! the step, its domain bound, and what the evaluation at the step's start found.

use crate::integrate::stepper::Rhs;
use crate::integrate::task::Task;
use crate::model::Model;
use crate::numbers::scalar::Scalar;

/// What the driver needs of a lane group's right-hand side besides evaluating it: each lane's
/// input over the step (V = v0 + slope tau) and what the evaluation at the step's start found.
pub trait LaneInputs<T: Scalar, const L: usize>: Rhs<T> {
    /// Set lane `i`'s input for the next attempt from time `t0` [s]: `v0` [V] at the step's
    /// start, `slope` [V/s].
    fn set_input(&mut self, i: usize, t0: f64, v0: f64, slope: f64);
    /// Lane `i`'s input as set: (v0 [V], slope [V/s]).
    fn input(&self, i: usize) -> (f64, f64);
    /// Lane `i`'s (Ff [N], dg/dt [m/s]) at the state its last step started from.
    fn at_start(&self, i: usize) -> (T, T);
}

impl<T: Scalar, const N: usize, const EXTRAS: bool, const L: usize> LaneInputs<T, L> for ModelRhs<'_, T, N, EXTRAS, L> {
    #[inline(always)]
    fn set_input(&mut self, i: usize, t0: f64, v0: f64, slope: f64) {
        self.t0[i] = t0;
        self.v0[i] = v0;
        self.slope[i] = slope;
    }
    #[inline(always)]
    fn input(&self, i: usize) -> (f64, f64) {
        (self.v0[i], self.slope[i])
    }
    #[inline(always)]
    fn at_start(&self, i: usize) -> (T, T) {
        self.at_start[i]
    }
}

impl<'a, T: Scalar, const N: usize, const EXTRAS: bool, const L: usize> ModelRhs<'a, T, N, EXTRAS, L> {
    /// The right-hand side of `tasks` (lane i runs task i; lanes beyond them idle on the last
    /// one's model), with the presliding bound widened by the stepper's `slack`.
    pub fn for_tasks(tasks: &[Task<'a, T>], slack: f64) -> Self {
        let m = tasks.len();
        let lane = |i: usize| i.min(m - 1);
        let zero = T::from(0.0);
        ModelRhs {
            models: std::array::from_fn(|i| tasks[lane(i)].model),
            t0: [0.0; L],
            v0: [0.0; L],
            slope: [0.0; L],
            at_start: [(zero, zero); L],
            bound: std::array::from_fn(|i| tasks[lane(i)].model.presliding_bound() * (1.0 + slack) + 1e-12),
        }
    }
}

/// The model under a linear input over one step, per lane: V = v0 + slope tau. Keeps each
/// lane's (Ff, dg/dt) from its evaluation at tau = 0, i.e. at the state the step starts from.
pub struct ModelRhs<'a, T: Scalar, const N: usize, const EXTRAS: bool, const L: usize> {
    pub models: [&'a Model<T>; L],
    /// the step's start [s] (the sampled force and the library read absolute time)
    pub t0: [f64; L],
    pub v0: [f64; L],
    pub slope: [f64; L],
    pub at_start: [(T, T); L],
    /// |Fh| bound of each lane's domain [N] (with the stepper's slack)
    pub bound: [f64; L],
}

impl<T: Scalar, const N: usize, const EXTRAS: bool, const L: usize> Rhs<T> for ModelRhs<'_, T, N, EXTRAS, L> {
    #[inline(always)]
    fn eval(&mut self, lane: usize, tau: f64, y: &[T], dy: &mut [T]) {
        let out = self.models[lane].rhs_impl::<N, EXTRAS>(
            self.t0[lane] + tau,
            T::from(self.v0[lane] + self.slope[lane] * tau),
            self.slope[lane],
            y,
            dy,
        );
        if tau == 0.0 {
            self.at_start[lane] = out;
        }
    }

    #[inline(always)]
    fn admissible(&self, lane: usize, y: &[T]) -> bool {
        !self.models[lane].is_diverged(y, self.bound[lane])
    }

    #[inline(always)]
    fn jacobian(&mut self, lane: usize, tau: f64, y: &[T], jac: &mut [T], dfdt: &mut [T]) {
        let (v0, s) = (self.v0[lane], self.slope[lane]);
        self.models[lane].jacobian(self.t0[lane] + tau, v0 + s * tau, s, y, jac, dfdt);
    }
}
