//! What every integrator offers the driver (`drive/`): one right-hand-side signature and one
//! "attempt a step on every lane" call. An integrator knows nothing of the physics or of the
//! input waveform; the driver sets each lane's input for the step before the attempt.
//!
//! Adaptive methods share their options ([`AdaptiveOptions`], with held steps for derivative
//! passes, [`Held`]) and their step-size control ([`Controller`]); each method computes only
//! its candidate step and error estimate. Adding an integrator means one file implementing
//! [`Stepper`] and one arm of `integrate::method::Method`.

use crate::numbers::scalar::Scalar;

/// State storage: a `Vec` for any size, or a fixed array that stays in registers; its elements
/// are `f64` for plain runs or dual numbers when derivatives are carried (see `numbers/scalar.rs`).
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

    /// [`Rhs::eval`] on every lane with `active[i]`, lane i at its own offset `tau[i]`. The
    /// steppers call this once per stage, so an implementation may compute the lanes together
    /// as vector arithmetic (`lanes/mod.rs`); by default it is one lane at a time.
    #[inline(always)]
    fn eval_lanes<S: State<Elem = T>, const L: usize>(
        &mut self,
        tau: &[f64; L],
        ys: &[S; L],
        dys: &mut [S; L],
        active: &[bool; L],
    ) {
        for i in 0..L {
            if active[i] {
                self.eval(i, tau[i], ys[i].as_ref(), dys[i].as_mut());
            }
        }
    }

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

/// Tolerances and limits of an adaptive method (one set per lane).
#[derive(Clone, Debug)]
pub struct AdaptiveOptions {
    /// relative tolerance [-]
    pub rtol: f64,
    /// absolute tolerance, in units of each component's `scale` [-]
    pub atol: f64,
    /// characteristic magnitude of each state component (its unit); `inf` leaves a component
    /// out of the error norm
    pub scale: Vec<f64>,
    /// first trial step [s]
    pub h_init: f64,
    /// below this step the run is declared divergent [s]
    pub h_min: f64,
    /// largest step [s]
    pub h_max: f64,
    /// Steps to take instead of choosing them (empty: adaptive): see [`Held`].
    pub held: Held,
}

/// The steps another run accepted [s] and the states it reached with them (row-major, one
/// state per step). A run given them takes exactly those steps, accepting each, and after
/// each step sets its state's values to the other run's (keeping any derivative parts): how
/// derivatives are carried along an adaptive run with its steps held. A replay alone would
/// drift from the run it follows by rounding, and an explicit method in a stiff phase, whose
/// steps sit at the stability limit, can amplify that drift until the error control (which a
/// replay does not have) would have stepped in.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Held {
    pub steps: Vec<f64>,
    pub states: Vec<f64>,
    /// `method="auto"`: the numbers of accepted steps after which the run changed method
    /// (explicit to implicit, then back, ...; empty: it never did)
    pub switches: Vec<u64>,
}

impl Held {
    pub fn is_empty(&self) -> bool {
        self.steps.is_empty()
    }
}

impl AdaptiveOptions {
    /// The step lane `i` tries next: its own proposal, or the next held step (`None` when the
    /// held steps ran out).
    #[inline(always)]
    pub(crate) fn next_step(&self, proposal: f64, taken: usize) -> Option<f64> {
        if self.held.is_empty() {
            Some(proposal)
        } else {
            self.held.steps.get(taken).copied()
        }
    }

    /// After held step `taken` (counted from 0), set the values of `y` to the held state.
    #[inline(always)]
    pub(crate) fn pin<T: Scalar>(&self, taken: usize, y: &mut [T]) {
        let d = y.len();
        if let Some(row) = self.held.states.get(taken * d..(taken + 1) * d) {
            for (x, v) in y.iter_mut().zip(row) {
                x.set_value(*v);
            }
        }
    }
}

/// Counters of an adaptive run.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct AdaptiveStats {
    pub accepted: u64,
    pub rejected: u64,
    pub evaluations: u64,
}

/// The message of a lane whose held steps ran out before its end.
pub(crate) const HELD_EXHAUSTED: &str = "the held steps ended before the run did";

/// The error norm given to a step whose result the model rules out (|Fh| beyond its bound):
/// rejected and halved, whatever the estimate said.
pub const OUT_OF_DOMAIN: f64 = f64::MAX;

/// The step-size control every adaptive method shares: an elementary controller on the
/// scaled error norm `err` of a step (accepted at err <= 1), new step = step x 0.9 err^(-1/q)
/// within [0.2, `max_growth`] after an acceptance and [0.1, 0.9] after a rejection, q the
/// order of the embedded estimate plus one.
#[derive(Clone, Copy, Debug)]
pub struct Controller {
    /// 1 / q
    pub exponent: f64,
    /// largest growth of the step after an acceptance
    pub max_growth: f64,
}

impl Controller {
    /// The next step [s] after accepting `step` with error `err`: grown unless the step was cut
    /// short to land on a breakpoint (`last`) and would grow, never above `o.h_max`.
    #[inline(always)]
    pub fn after_accept(&self, err: f64, step: f64, last: bool, h: f64, o: &AdaptiveOptions) -> f64 {
        let grow = if err == 0.0 {
            self.max_growth
        } else {
            (0.9 * err.powf(-self.exponent)).clamp(0.2, self.max_growth)
        };
        if !last || grow < 1.0 {
            (step * grow).min(o.h_max)
        } else {
            h
        }
    }

    /// The step [s] to retry after rejecting `step` with error `err` (NaN when the state blew
    /// up), and the attempt's outcome: rejected, or failed when the step fell below `o.h_min`.
    #[inline(always)]
    pub fn after_reject(&self, err: f64, step: f64, o: &AdaptiveOptions) -> (f64, Attempt) {
        let shrink = if err == OUT_OF_DOMAIN {
            0.5
        } else if err.is_finite() {
            (0.9 * err.powf(-self.exponent)).clamp(0.1, 0.9)
        } else {
            0.1
        };
        let h = step * shrink;
        if h < o.h_min {
            (h, Attempt::Failed(format!("step size fell below {:.1e} s", o.h_min)))
        } else {
            (h, Attempt::Rejected)
        }
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
    /// Relative slack of the bound the right-hand side's `admissible` checks (implicit steps
    /// reject a step beyond it); by default the same as [`Stepper::bound_slack`].
    fn admissible_slack(&self) -> f64 {
        self.bound_slack()
    }
    /// `Some(accepted)` once, right after the attempt in which `lane` changed method (after
    /// `accepted` accepted steps; `method="auto"`); `None` otherwise.
    fn take_switch(&mut self, _lane: usize) -> Option<u64> {
        None
    }
    /// What to do instead when `lane`'s run crawls (`crawl::CrawlWatch`; adaptive steppers only).
    fn crawl_hint(&self, _lane: usize) -> &'static str {
        ""
    }
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
