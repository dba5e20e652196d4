//! What every integrator offers the driver (`drive.rs`): one right-hand-side signature and one
//! "attempt a step on every lane" call. An integrator knows nothing of the physics or of the
//! input waveform; the driver sets each lane's input for the step before the attempt.
//!
//! Adding an integrator means one file implementing [`Stepper`] and one arm of
//! `drive::Method`.

use crate::scalar::Scalar;

/// State storage: a `Vec` for any size, or a fixed array that stays in registers; its elements
/// are `f64` for plain runs or dual numbers when derivatives are carried (see `scalar.rs`).
pub trait State: AsRef<[Self::Elem]> + AsMut<[Self::Elem]> + Clone {
    type Elem: Scalar;
}
impl<T: Scalar, const D: usize> State for [T; D] {
    type Elem = T;
}
impl<T: Scalar> State for Vec<T> {
    type Elem = T;
}

/// A right-hand side over one step: `dy = f(y)` for `lane` at offset `tau` [s] from the start
/// of the step (the input is linear over a step). A trait rather than a bare closure so that
/// implementations can be `#[inline(always)]`; closures implement it too.
pub trait Rhs<T: Scalar = f64> {
    fn eval(&mut self, lane: usize, tau: f64, y: &[T], dy: &mut [T]);

    /// Whether `y` lies in the system's domain (for the model: |Fh| within its bound). Adaptive
    /// implicit steps reject a step that leaves it. Default: everywhere.
    fn admissible(&self, _lane: usize, _y: &[T]) -> bool {
        true
    }

    /// The Jacobian df/dy (row-major, `y.len()` squared) and df/dt at offset `tau`, for
    /// implicit integrators. By default central differences (for tests and toy systems with
    /// states and times of order one; the model overrides this with its analytic Jacobian).
    fn jacobian(&mut self, lane: usize, tau: f64, y: &[T], jac: &mut [T], dfdt: &mut [T]) {
        let d = y.len();
        let (mut yp, mut fp, mut fm) = (y.to_vec(), vec![T::zero(); d], vec![T::zero(); d]);
        for c in 0..d {
            let h = 1e-7 * y[c].value().abs().max(1e-7);
            yp[c] = y[c] + h;
            self.eval(lane, tau, &yp, &mut fp);
            yp[c] = y[c] - h;
            self.eval(lane, tau, &yp, &mut fm);
            yp[c] = y[c];
            for r in 0..d {
                jac[r * d + c] = (fp[r] - fm[r]) / (2.0 * h);
            }
        }
        let h = 1e-6 * (1.0 + tau.abs());
        self.eval(lane, tau + h, y, &mut fp);
        self.eval(lane, tau - h, y, &mut fm);
        for r in 0..d {
            dfdt[r] = (fp[r] - fm[r]) / (2.0 * h);
        }
    }
}

impl<F: FnMut(usize, f64, &[f64], &mut [f64])> Rhs<f64> for F {
    #[inline(always)]
    fn eval(&mut self, lane: usize, tau: f64, y: &[f64], dy: &mut [f64]) {
        self(lane, tau, y, dy)
    }
}

/// What became of one lane's attempt.
#[derive(Clone, Debug, PartialEq)]
pub enum Attempt {
    /// The lane did not take part (inactive).
    Idle,
    /// The state advanced by `step` [s]; `last` when the step was stretched or cut to land on
    /// the segment's end exactly.
    Accepted { step: f64, last: bool },
    /// Error too large: the state is unchanged, retry with the stepper's smaller proposal.
    Rejected,
    /// The step size collapsed: the run cannot continue (the message says why).
    Failed(String),
}

/// An integrator advancing `L` independent systems ("lanes") attempt by attempt, stage by
/// stage, so one core works on several dependency chains at once (one trajectory alone is
/// latency-bound). Each lane's arithmetic is exactly that of a one-lane run.
pub trait Stepper<S: State, const L: usize> {
    /// Fixed-step methods take exactly this step [s] every time; the driver then counts steps
    /// and computes step times as multiples of it (exact, reproducible across restarts).
    const FIXED_STEP: bool;
    /// True when every accepted step evaluated the right-hand side at the state it started from
    /// (its first stage), so observers may reuse what that evaluation computed.
    const EVALUATES_START: bool;
    /// Relative slack on the presliding-force bound before a state counts as diverged: the
    /// method's local error may overshoot the bound by this much.
    fn bound_slack(&self) -> f64;
    /// Forget anything carried from a previous step of `lane` (first-same-as-last stages): it
    /// starts anew, or the input's slope changed.
    fn restart(&mut self, lane: usize);
    /// Try one step on every lane with `active[i]`, from time `t[i]`, never past `end[i]`.
    /// Accepted steps overwrite `ys[i]`.
    fn attempt<F: Rhs<S::Elem>>(
        &mut self,
        f: &mut F,
        ys: &mut [S; L],
        t: &[f64; L],
        end: &[f64; L],
        active: &[bool; L],
    ) -> [Attempt; L];
}
