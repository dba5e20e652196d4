//! A run as the driver and every runner see it: the [`Task`] (a model, an input, a span, a
//! start), the [`Observer`] that sees its accepted states, how it ends ([`LaneEnd`] or
//! [`SimError`]), where a handed-over run resumes ([`Resume`]) and its adaptive options.

use crate::integrate::crawl::CrawlWatch;
use crate::integrate::stepper::{AdaptiveOptions, Held};
use crate::model::Model;
use crate::numbers::scalar::Scalar;
use crate::physics::waveform::PiecewiseLinear;

/// How often (in attempts) a running group looks at the cancel flag.
pub(crate) const CANCEL_CHECK_ATTEMPTS: usize = 1 << 14;
/// Smallest step an adaptive method may take before the run counts as diverged [s].
const ADAPTIVE_H_MIN: f64 = 1e-14;

/// Why a run stopped without a result.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum SimError {
    /// Bad input (parameters, step size, waveform, initial state); the message names what.
    #[error("{0}")]
    Input(String),
    /// The state left its physical bounds or became non-finite at time `t` [s].
    #[error("{message}")]
    Diverged { t: f64, message: String },
}

impl From<crate::error::InputError> for SimError {
    fn from(e: crate::error::InputError) -> Self {
        SimError::Input(e.0)
    }
}

/// One run: a model under an input from `t_start` to `t_end` [s], starting from `y0`.
#[derive(Clone, Copy, Debug)]
pub struct Task<'a, T: Scalar = f64> {
    pub model: &'a Model<T>,
    pub wave: &'a PiecewiseLinear,
    pub t_start: f64,
    pub t_end: f64,
    pub y0: &'a [T],
}

/// How a run ended.
#[derive(Clone, Debug, PartialEq)]
pub enum LaneEnd {
    /// Reached `t_end` after `steps` accepted steps, the smallest `min_step` [s] long.
    Finished { steps: u64, min_step: f64 },
    /// Diverged at time `t` [s] (the state there is the run's final state); `why` for adaptive
    /// methods whose step collapsed; `v_last` [m/s] the main body's velocity at the last state
    /// within bounds (for step hints).
    Diverged { t: f64, why: Option<String>, v_last: f64 },
}

/// Sees a run's states as they are accepted (states of `f64`, or of dual numbers when
/// derivatives are carried).
pub trait Observer<T: Scalar = f64> {
    /// Task `task` starts at time `t` [s] in state `y`.
    fn start(&mut self, task: usize, t: f64, y: &[T]);
    /// Task `task` accepted a step of `span` [s] ending at time `t` [s] in state `y`, with the
    /// commanded voltage `v_cmd` [V] there; `start` is the model's (Ff [N], dg/dt [m/s]) at the
    /// state the step started from when the integrator evaluated it (RK4's first stage);
    /// `last` marks the run's final step.
    #[allow(clippy::too_many_arguments)]
    fn step(&mut self, task: usize, t: f64, span: f64, y: &[T], v_cmd: f64, start: Option<(T, T)>, last: bool);

    /// An adaptive method's accepted step [s] for task `task`, exactly as the method took it
    /// (called before [`Observer::step`]; the span there is the difference of two times).
    fn accepted_step(&mut self, _task: usize, _step: f64) {}

    /// Task `task` (a `method="auto"` run) changed method after `accepted` accepted steps: to
    /// the implicit one, or back after a failed probation (the calls alternate).
    fn switched(&mut self, _task: usize, _accepted: u64) {}
}

/// Where a run handed over by the vector path (`method="auto"`, a lane whose run turned stiff)
/// continues: its task starts at the hand-over time and state, and these carry
/// what the run had counted so far.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Resume {
    /// accepted steps so far, and the smallest [s]
    pub steps: u64,
    pub min_step: f64,
    /// the main body's velocity at the last state [m/s]
    pub v_last: f64,
    /// the explicit step the run had proposed next [s] (its trial step is a multiple)
    pub h: f64,
    /// the run's watch on its pace (`integrate/crawl.rs`)
    pub watch: CrawlWatch,
}

/// Adaptive options for a task: error scales from the model and the input's peak; `held`
/// steps to take instead of choosing them (see [`AdaptiveOptions::held`]).
pub(crate) fn adaptive_options<T: Scalar>(
    task: &Task<T>,
    rtol: f64,
    atol: f64,
    first_step: f64,
    held: &Held,
) -> AdaptiveOptions {
    let v_max = task.wave.peak();
    AdaptiveOptions {
        rtol,
        atol,
        scale: task.model.state_scales(v_max),
        h_init: first_step,
        h_min: ADAPTIVE_H_MIN,
        h_max: ((task.t_end - task.t_start) / 10.0).max(first_step),
        held: held.clone(),
    }
}
