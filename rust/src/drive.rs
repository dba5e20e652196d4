//! The one driver every run goes through, single trajectories and batch points alike: it plans
//! the steps, walks the input's breakpoints, sets each lane's input for the step, asks the
//! integrator ([`Stepper`]) to attempt it, checks the model's divergence criterion, and hands
//! every accepted state to an [`Observer`] (saving a trajectory, recording sensor readings,
//! accumulating sweep metrics are observers).
//!
//! Up to `L` runs ("lanes") of one state layout advance together, stage by stage (see
//! `stepper.rs`); a lane's arithmetic is exactly that of a run alone, so results do not depend on
//! how runs are grouped.

use std::marker::PhantomData;
use std::sync::atomic::{AtomicBool, Ordering};

use crate::dopri5::Dopri5;
use crate::stepper::{AdaptiveOptions, Held};
use crate::lanes::{simd_arch, LaneExp, LibmExp, PlainLanes};
use crate::lanes_dopri5::{run_dopri5_lanes, Handoff};
use crate::lanes_rk4::run_rk4_lanes;
use crate::model::{with_state_size, Model};
use crate::rk4::Rk4;
use crate::rodas4::Rodas4;
use crate::scalar::Scalar;
use crate::crawl::CrawlWatch;
use crate::stepper::{Attempt, Rhs, State, Stepper};
use crate::switching::Switching;
use crate::waveform::{Cursor, PiecewiseLinear};

/// RK4's stability limit on the imaginary axis is 2 sqrt 2; keep a margin.
pub const RK4_STABLE_OMEGA_DT: f64 = 2.5;
/// How often (in attempts) a running group looks at the cancel flag.
pub(crate) const CANCEL_CHECK_ATTEMPTS: usize = 1 << 14;
/// Smallest step an adaptive method may take before the run counts as diverged [s].
const ADAPTIVE_H_MIN: f64 = 1e-14;

/// Integration method of a run.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Method {
    /// Fixed-step classical RK4 with step `dt` [s] (the reference).
    Rk4 { dt: f64 },
    /// Adaptive Dormand-Prince 5(4); `atol` in units of each state's natural scale (see
    /// [`Model::state_scales`]), `first_step` [s] the first trial step.
    Dopri5 { rtol: f64, atol: f64, first_step: f64 },
    /// Adaptive Rodas4 (linearly implicit, L-stable: steps set by accuracy in the stiff sliding
    /// phases); tolerances and first step as for `Dopri5`.
    Rodas4 { rtol: f64, atol: f64, first_step: f64 },
    /// Dormand-Prince at `rtol`, `atol`; a run that turns stiff tries a Rodas4 step (tolerances
    /// `switching::IMPLICIT_TOL_FACTOR` times looser) and goes on with Rodas4 if it pays
    /// (`stiffness.rs`, `switching.rs`).
    Auto { rtol: f64, atol: f64, first_step: f64 },
}

impl Method {
    /// The method called `name` ("rk4", "dopri5") with these settings, validated.
    pub fn from_name(name: &str, dt: f64, rtol: f64, atol: f64, first_step: f64) -> Result<Self, String> {
        let m = match name {
            "rk4" => Method::Rk4 { dt },
            "dopri5" => Method::Dopri5 {
                rtol,
                atol,
                first_step,
            },
            "rodas4" => Method::Rodas4 {
                rtol,
                atol,
                first_step,
            },
            "auto" => Method::Auto { rtol, atol, first_step },
            other => {
                return Err(format!(
                    "parameter 'method' must be 'rk4', 'dopri5', 'rodas4' or 'auto', got '{other}'"
                ))
            }
        };
        m.validate()?;
        Ok(m)
    }

    /// The fixed step [s] of a fixed-step method (RK4); `None` for an adaptive one.
    pub fn fixed_step(&self) -> Option<f64> {
        match *self {
            Method::Rk4 { dt } => Some(dt),
            Method::Dopri5 { .. } | Method::Rodas4 { .. } | Method::Auto { .. } => None,
        }
    }

    /// Whether every step is the same, set beforehand (RK4).
    pub fn is_fixed(&self) -> bool {
        self.fixed_step().is_some()
    }

    /// The first step [s]: RK4's step, or an adaptive method's first trial step.
    pub fn first_step(&self) -> f64 {
        match *self {
            Method::Rk4 { dt } => dt,
            Method::Dopri5 { first_step, .. } | Method::Rodas4 { first_step, .. } | Method::Auto { first_step, .. } => {
                first_step
            }
        }
    }

    /// Refuse tolerances or steps that are not positive and finite.
    pub fn validate(&self) -> Result<(), String> {
        match *self {
            Method::Rk4 { dt } => {
                if !(dt.is_finite() && dt > 0.0) {
                    return Err(format!("parameter 'dt' must be positive and finite, got {dt}"));
                }
            }
            Method::Dopri5 {
                rtol,
                atol,
                first_step,
            }
            | Method::Rodas4 {
                rtol,
                atol,
                first_step,
            }
            | Method::Auto { rtol, atol, first_step } => {
                if !(rtol > 0.0 && atol > 0.0 && rtol.is_finite() && atol.is_finite()) {
                    return Err(format!(
                        "'rtol' and 'atol' must be positive, got {rtol}, {atol}"
                    ));
                }
                if !(first_step.is_finite() && first_step > 0.0) {
                    return Err(format!(
                        "parameter 'first_step' must be positive and finite, got {first_step}"
                    ));
                }
            }
        }
        Ok(())
    }
}

/// Why a run stopped without a result.
#[derive(Clone, Debug, PartialEq)]
pub enum SimError {
    /// Bad input (parameters, step size, waveform, initial state); the message names what.
    Input(String),
    /// The state left its physical bounds or became non-finite at time `t` [s].
    Diverged { t: f64, message: String },
}

impl std::fmt::Display for SimError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            SimError::Input(m) => write!(f, "{m}"),
            SimError::Diverged { message, .. } => write!(f, "{message}"),
        }
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
    fn step(
        &mut self,
        task: usize,
        t: f64,
        span: f64,
        y: &[T],
        v_cmd: f64,
        start: Option<(T, T)>,
        last: bool,
    );

    /// An adaptive method's accepted step [s] for task `task`, exactly as the method took it
    /// (called before [`Observer::step`]; the span there is the difference of two times).
    fn accepted_step(&mut self, _task: usize, _step: f64) {}

    /// Task `task` (a `method="auto"` run) changed method after `accepted` accepted steps: to
    /// the implicit one, or back after a failed probation (the calls alternate).
    fn switched(&mut self, _task: usize, _accepted: u64) {}
}

/// Number of RK4 steps of `dt` from `t_start` to `t_end`, refusing a `dt` that does not divide
/// them into whole steps or the input's breakpoints, or that the structure's highest mode or a
/// fast effect lag makes unstable. The message names the parameter and a step that works.
pub fn plan_steps(
    model: &Model,
    wave: &PiecewiseLinear,
    t_start: f64,
    t_end: f64,
    dt: f64,
) -> Result<usize, SimError> {
    if !(dt.is_finite() && dt > 0.0) {
        return Err(SimError::Input(format!(
            "parameter 'dt' must be positive and finite, got {dt}"
        )));
    }
    check_span(t_start, t_end)?;
    let whole = |x: f64| (x / dt - (x / dt).round()).abs() <= 1e-6;
    let suggestion = || match fitting_step(wave, t_start, t_end, dt) {
        Some(d) => format!("dt = {d:e} s divides the run and every breakpoint"),
        None => "choose a dt that divides t_start, t_end and every breakpoint time".into(),
    };
    if !whole(t_start) {
        return Err(SimError::Input(format!(
            "t_start = {t_start:e} s is not a whole number of steps dt = {dt:e} s; \
             start on a multiple of dt, or use {}",
            suggestion()
        )));
    }
    // a breakpoint off the step grid is named first: it is usually the cause (a rise time that
    // is not a multiple of dt), even when t_end does not divide either
    if let Some(ti) = wave.misaligned(dt, t_end) {
        return Err(SimError::Input(format!(
            "dt = {dt:e} s does not divide the waveform breakpoint at t = {ti:e} s (where the input \
             changes slope, e.g. the end of a rise; breakpoints must fall on step boundaries); {}",
            suggestion()
        )));
    }
    if let Some(ti) = model.external.as_ref().and_then(|x| x.knots.misaligned(dt, t_end)) {
        return Err(SimError::Input(format!(
            "dt = {dt:e} s does not divide the external force's sample at t = {ti:e} s (its samples \
             must fall on step boundaries with RK4); sample the force on a multiple of dt, or use an \
             adaptive method"
        )));
    }
    let steps = ((t_end - t_start) / dt).round();
    if (steps * dt - (t_end - t_start)).abs() > 1e-6 * dt || steps < 1.0 {
        return Err(SimError::Input(format!(
            "dt = {dt:e} s does not divide t_end = {t_end:e} s into whole steps; {}",
            suggestion()
        )));
    }
    // a first-order lag much faster than the step makes its state stiff: RK4 would diverge
    for (name, tau) in model.effects.lags() {
        if tau > 0.0 && tau * RK4_STABLE_OMEGA_DT < dt {
            return Err(SimError::Input(format!(
                "effect parameter '{name}' = {tau:e} s is too short for dt = {dt:e} s (RK4 needs dt <= {:.3e} s); \
                 use a smaller dt, or 0 to switch the effect off",
                tau * RK4_STABLE_OMEGA_DT
            )));
        }
    }
    let w = model.mech.highest_frequency();
    if w * dt > RK4_STABLE_OMEGA_DT {
        return Err(SimError::Input(format!(
            "dt = {dt:e} s is unstable for the highest structural mode ({w:.4e} rad/s); \
             use dt <= {:.3e} s",
            RK4_STABLE_OMEGA_DT / w
        )));
    }
    Ok(steps as usize)
}

/// An RK4 step not above `dt` [s] that puts `t_start`, `t_end` and every breakpoint of `wave` in
/// between on the step grid (steps count from t = 0): the largest round one (1, 2, 2.5, 4 or 5
/// times a power of ten) within a factor 10 below `dt`, else the largest t_end / k; `None` if
/// neither is found.
pub fn fitting_step(wave: &PiecewiseLinear, t_start: f64, t_end: f64, dt: f64) -> Option<f64> {
    if !(dt.is_finite() && dt > 0.0 && t_end.is_finite() && t_end > 0.0) {
        return None;
    }
    let fits = |d: f64| {
        let whole = |x: f64| ((x / d) - (x / d).round()).abs() <= 1e-6;
        whole(t_start) && whole(t_end) && wave.misaligned(d, t_end).is_none()
    };
    let decade = dt.log10().floor();
    let round = (0..3)
        .flat_map(|k| [5.0, 4.0, 2.5, 2.0, 1.0].map(|m| m * 10f64.powf(decade - k as f64)))
        .map(|d| format!("{d:.6e}").parse::<f64>().unwrap_or(d)) // exactly the printed value
        .filter(|&d| d <= dt * (1.0 + 1e-12) && d >= dt / 10.0)
        .find(|&d| fits(d));
    if round.is_some() {
        return round;
    }
    let first = (t_end / dt * (1.0 - 1e-12)).ceil().max(1.0);
    if first > 1e13 {
        return None;
    }
    (0..100_000u64).map(|i| t_end / (first + i as f64)).find(|&d| fits(d))
}

/// Refuse a time span that is not finite or not increasing.
pub fn check_span(t_start: f64, t_end: f64) -> Result<(), SimError> {
    if !(t_end.is_finite() && t_end > 0.0) {
        return Err(SimError::Input(format!(
            "parameter 't_end' must be positive and finite, got {t_end}"
        )));
    }
    if !(t_start.is_finite() && t_start >= 0.0 && t_start < t_end) {
        return Err(SimError::Input(format!(
            "parameter 't_start' must be finite, non-negative and before t_end = {t_end:e} s, got {t_start}"
        )));
    }
    Ok(())
}

/// Check a run's settings before any work: the span, and for RK4 the step plan.
pub fn check_task(task: &Task, method: &Method) -> Result<(), SimError> {
    method.validate().map_err(SimError::Input)?;
    task.model
        .check_state(task.y0)
        .map_err(SimError::Input)?;
    match *method {
        Method::Rk4 { dt } => plan_steps(task.model, task.wave, task.t_start, task.t_end, dt).map(|_| ()),
        Method::Dopri5 { .. } | Method::Rodas4 { .. } | Method::Auto { .. } => check_span(task.t_start, task.t_end),
    }
}

/// The message of a divergence at time `t` [s] in state `y` with RK4 step `dt` [s], `v_last`
/// [m/s] the main body's velocity at the last state that was still within bounds: where the state
/// left its bounds and a step to try. The step comes from the stability estimate of the friction
/// state at `v_last` (the diverged state's own velocity is meaningless), never below dt / 64,
/// and is fitted to the run's breakpoints and span when `wave` is given.
pub fn divergence_message(
    model: &Model,
    dt: f64,
    t: f64,
    y: &[f64],
    v_last: f64,
    fit: Option<(&PiecewiseLinear, f64, f64)>,
) -> String {
    let l = model.layout;
    let stiff = model.friction.sliding_stiffness(v_last);
    let w = model.mech.highest_frequency().max(stiff);
    let stable = if w.is_finite() && w > 0.0 {
        RK4_STABLE_OMEGA_DT / w
    } else {
        f64::NAN
    };
    // RK4 failed at dt: the hint is below it, and a blown-up estimate is not trusted below dt/64
    let raw = if stable.is_finite() { stable.clamp(dt / 64.0, dt / 2.0) } else { dt / 4.0 };
    let hint = fit
        .and_then(|(wave, t0, t1)| fitting_step(wave, t0, t1, raw))
        .unwrap_or(raw);
    format!(
        "integration diverged at t = {t:.6e} s (Fh = {:.4e} N, bound {:.4e} N; v1 = {:.4e} m/s the step \
         before): dt = {dt:e} s is too large for the friction state's stiffness during sliding \
         (stability estimate there: dt <= {stable:.2e} s); try dt = {hint:e} s, or method 'rodas4' \
         (implicit, no such limit)",
        y[l.fh],
        model.presliding_bound(),
        v_last
    )
}

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
    /// the run's watch on its pace (`crawl.rs`)
    pub watch: CrawlWatch,
}

/// Advance up to `L` tasks of one state layout together (`tasks[i]` on lane i; unused lanes idle)
/// from their initial states in `ys`, which end holding the final states, with `rhs` their
/// right-hand side (see [`ModelRhs::for_tasks`]). `first` is the index the observer sees for
/// lane 0; `dt` [s] the step of a fixed-step stepper; `resume`: tasks that continue a run
/// (their observer was started already, their counts go on). `None` if cancelled. Always
/// inlined: the caller may compile it for the processor's vector width (`run_tasks`).
#[allow(clippy::too_many_arguments)]
#[inline(always)]
fn drive_lanes<S, St, O, R, const L: usize>(
    tasks: &[Task<S::Elem>],
    first: usize,
    dt: f64,
    stepper: &mut St,
    rhs: &mut R,
    ys: &mut [S; L],
    observer: &mut O,
    cancel: &AtomicBool,
    resume: Option<&[Resume]>,
) -> Option<Vec<LaneEnd>>
where
    S: State,
    St: Stepper<S, L>,
    O: Observer<S::Elem>,
    R: LaneInputs<S::Elem, L>,
{
    let m = tasks.len();
    let lane = |i: usize| i.min(m - 1); // idle lanes point at a real model
    let slack = stepper.bound_slack();
    let bound: [f64; L] = std::array::from_fn(|i| {
        tasks[lane(i)].model.presliding_bound() * (1.0 + slack) + 1e-12
    });
    let mut active = [false; L];
    let mut t = [0.0; L];
    let mut end = [0.0; L];
    let mut cursor = [Cursor::default(); L];
    // fixed step: the step index of each lane from t = 0 (step times are exact multiples)
    let mut k = [0usize; L];
    let mut k_end = [0usize; L];
    let mut steps = [0u64; L];
    let mut min_step = [f64::INFINITY; L];
    let mut watch = [CrawlWatch::new(0.0); L];
    let mut v_last = [0.0; L];
    let mut out: Vec<Option<LaneEnd>> = vec![None; m];
    for i in 0..m {
        let task = &tasks[i];
        active[i] = true;
        t[i] = task.t_start;
        watch[i] = CrawlWatch::new(task.t_start);
        cursor[i] = Cursor::at(task.wave, task.t_start);
        if St::FIXED_STEP {
            k[i] = (task.t_start / dt).round() as usize;
            k_end[i] = k[i] + ((task.t_end - task.t_start) / dt).round() as usize;
        }
        stepper.restart(i);
        v_last[i] = ys[i].as_ref()[task.model.layout.dof].value();
        match resume {
            Some(r) => (steps[i], min_step[i], v_last[i], watch[i]) = (r[i].steps, r[i].min_step, r[i].v_last, r[i].watch),
            None => observer.start(first + i, task.t_start, ys[i].as_ref()),
        }
    }
    let mut attempts = 0usize;
    loop {
        if attempts.is_multiple_of(CANCEL_CHECK_ATTEMPTS) && cancel.load(Ordering::Relaxed) {
            return None;
        }
        attempts += 1;
        let mut any = false;
        for i in 0..m {
            if !active[i] {
                continue;
            }
            let wave = tasks[i].wave;
            let (v0, s) = if St::FIXED_STEP {
                let t0 = k[i] as f64 * dt;
                t[i] = t0;
                // breakpoints sit on step boundaries: the step's midpoint names its segment
                let probe = t0 + 0.5 * dt;
                cursor[i].advance(wave, probe);
                end[i] = t0 + dt;
                cursor[i].input(wave, t0, probe)
            } else {
                if cursor[i].advance(wave, t[i]) {
                    stepper.restart(i); // the input's slope changed
                }
                end[i] = cursor[i].next_breakpoint(wave, t[i]).min(tasks[i].t_end);
                if let Some(x) = &tasks[i].model.external {
                    // a knot of the sampled force ends a step too (its slope changes there)
                    let knot = x.next_knot(t[i]);
                    // (the force is continuous there, so the method need not restart)
                    if knot < end[i] {
                        end[i] = knot;
                    }
                }
                cursor[i].input(wave, t[i], t[i])
            };
            rhs.set_input(i, t[i], v0, s);
            any = true;
        }
        if !any {
            break;
        }
        let results = stepper.attempt(rhs, ys, &t, &end, &active);
        for i in 0..m {
            let (step, last) = match &results[i] {
                Attempt::Accepted { step, last } => (*step, *last),
                Attempt::Failed(why) => {
                    active[i] = false;
                    out[i] = Some(LaneEnd::Diverged {
                        t: t[i],
                        why: Some(why.clone()),
                        v_last: v_last[i],
                    });
                    continue;
                }
                Attempt::Idle | Attempt::Rejected => continue,
            };
            let (t_new, span, done) = if St::FIXED_STEP {
                k[i] += 1;
                ((k[i] as f64) * dt, dt, k[i] == k_end[i])
            } else {
                let t_new = if last { end[i] } else { t[i] + step };
                (t_new, t_new - t[i], t_new >= tasks[i].t_end)
            };
            t[i] = t_new;
            let y = ys[i].as_ref();
            if tasks[i].model.is_diverged(y, bound[i]) {
                active[i] = false;
                out[i] = Some(LaneEnd::Diverged {
                    t: t_new,
                    why: None,
                    v_last: v_last[i],
                });
                continue;
            }
            v_last[i] = y[tasks[i].model.layout.dof].value();
            steps[i] += 1;
            min_step[i] = min_step[i].min(span);
            if let Some(n) = stepper.take_switch(i) {
                observer.switched(first + i, n);
            }
            if !St::FIXED_STEP && !done {
                if let Some(why) = watch[i].observe(steps[i], t_new, tasks[i].t_end, stepper.crawl_hint(i)) {
                    active[i] = false;
                    out[i] = Some(LaneEnd::Diverged { t: t_new, why: Some(why), v_last: v_last[i] });
                    continue;
                }
            }
            let start = St::EVALUATES_START.then(|| rhs.at_start(i));
            let (v0, slope) = rhs.input(i);
            let v_cmd = v0 + slope * step;
            if !St::FIXED_STEP {
                observer.accepted_step(first + i, step);
            }
            observer.step(first + i, t_new, span, y, v_cmd, start, done);
            if done {
                active[i] = false;
                out[i] = Some(LaneEnd::Finished {
                    steps: steps[i],
                    min_step: min_step[i],
                });
            }
        }
    }
    Some(
        out.into_iter()
            .map(|o| o.expect("every lane ends"))
            .collect(),
    )
}

/// Adaptive options for a task: error scales from the model and the input's peak; `held`
/// steps to take instead of choosing them (see [`AdaptiveOptions::held`]).
pub(crate) fn adaptive_options<T: Scalar>(task: &Task<T>, rtol: f64, atol: f64, first_step: f64, held: &Held) -> AdaptiveOptions {
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

/// Run one group of up to `L` tasks of one state layout with `method` (`D` components fixed at
/// compile time, or 0 for any; `rhs_for` builds the group's right-hand side from the tasks and
/// the stepper's bound slack), appending each task's end and final state to `out`; `None` if
/// cancelled.
#[allow(clippy::too_many_arguments)]
#[inline(always)]
fn run_group<'a, S, O, R, const D: usize, const L: usize>(
    chunk: &[Task<'a, S::Elem>],
    first: usize,
    method: &Method,
    held: &Held,
    zero: S,
    rhs_for: impl FnOnce(&[Task<'a, S::Elem>], f64) -> R,
    observer: &mut O,
    cancel: &AtomicBool,
    out: &mut Vec<(LaneEnd, Vec<S::Elem>)>,
    resume: Option<&[Resume]>,
) -> Option<()>
where
    S: State,
    O: Observer<S::Elem>,
    R: LaneInputs<S::Elem, L>,
{
    let task = |i: usize| &chunk[i.min(chunk.len() - 1)];
    let mut ys: [S; L] = std::array::from_fn(|i| {
        let mut y = zero.clone();
        y.as_mut().copy_from_slice(task(i).y0);
        y
    });
    let ends = match *method {
        Method::Rk4 { dt } => {
            let mut st: Rk4<S, L> = Rk4::new(dt, zero);
            let mut rhs = rhs_for(chunk, st.admissible_slack());
            drive_lanes(chunk, first, dt, &mut st, &mut rhs, &mut ys, observer, cancel, resume)?
        }
        Method::Dopri5 { rtol, atol, first_step } => {
            let opts = std::array::from_fn(|i| adaptive_options(task(i), rtol, atol, first_step, held));
            let mut st: Dopri5<S, L> = Dopri5::new(opts, zero);
            let mut rhs = rhs_for(chunk, st.admissible_slack());
            drive_lanes(chunk, first, 0.0, &mut st, &mut rhs, &mut ys, observer, cancel, resume)?
        }
        Method::Rodas4 { rtol, atol, first_step } => {
            let opts = std::array::from_fn(|i| adaptive_options(task(i), rtol, atol, first_step, held));
            let mut st: Rodas4<S, L, D> = Rodas4::new(opts, zero);
            let mut rhs = rhs_for(chunk, st.admissible_slack());
            drive_lanes(chunk, first, 0.0, &mut st, &mut rhs, &mut ys, observer, cancel, resume)?
        }
        Method::Auto { rtol, atol, first_step } => {
            let opts = std::array::from_fn(|i| adaptive_options(task(i), rtol, atol, first_step, held));
            let mut st: Switching<S, L, D> = Switching::new(opts, zero);
            if let Some(r) = resume {
                for (i, r) in r.iter().enumerate() {
                    st.start_trial(i, r.h, r.steps);
                }
            }
            let mut rhs = rhs_for(chunk, st.admissible_slack());
            drive_lanes(chunk, first, 0.0, &mut st, &mut rhs, &mut ys, observer, cancel, resume)?
        }
    };
    for (e, y) in ends.into_iter().zip(ys.iter()) {
        out.push((e, y.as_ref().to_vec()));
    }
    Some(())
}

/// An observer that sees task `i` of a list as task `index[i]` of another.
struct Renumbered<'o, 'i, O> {
    inner: &'o mut O,
    index: &'i [usize],
}

impl<T: Scalar, O: Observer<T>> Observer<T> for Renumbered<'_, '_, O> {
    #[inline(always)]
    fn start(&mut self, task: usize, t: f64, y: &[T]) {
        self.inner.start(self.index[task], t, y)
    }
    #[inline(always)]
    fn step(&mut self, task: usize, t: f64, span: f64, y: &[T], v_cmd: f64, start: Option<(T, T)>, last: bool) {
        self.inner.step(self.index[task], t, span, y, v_cmd, start, last)
    }
    #[inline(always)]
    fn accepted_step(&mut self, task: usize, step: f64) {
        self.inner.accepted_step(self.index[task], step)
    }
    #[inline(always)]
    fn switched(&mut self, task: usize, accepted: u64) {
        self.inner.switched(self.index[task], accepted)
    }
}

/// The vector drivers' part of a lane group run (see [`PlainGroups`]): every task's end, and the
/// runs `method="auto"` handed over to the implicit method; or `Fallback` when the vector drivers
/// do not run these tasks (another shape, or Rodas4).
enum LaneRun {
    Fallback,
    Ran { ends: Vec<Option<(LaneEnd, Vec<f64>)>>, handoffs: Vec<Handoff> },
}

/// The vector lane drivers over f64 tasks with `N` nodes and `D` state components (`EXTRAS`:
/// lag states beside the plain ones, see [`Model::lane_lags`](crate::model::Model::lane_lags)),
/// as one operation for `pulp` to compile once per instruction set: its `with_simd` runs inside
/// a function with that set's features enabled, and everything it calls is inlined into it
/// (closures are not: the call through `FnOnce` stays out of line, compiled for the baseline).
/// Only the two SoA drivers are in it: the lane-interleaved scalar code of the hand-overs and of
/// the fallback (`run_fixed`) gains nothing from vector instructions, so it is compiled once,
/// not once per instruction set (build time; the bits are the same either way).
struct PlainGroups<'t, 'a, O, E, const N: usize, const D: usize, const EXTRAS: bool, const L: usize> {
    tasks: &'t [Task<'a>],
    method: &'t Method,
    observer: &'t mut O,
    cancel: &'t AtomicBool,
    _exp: PhantomData<E>,
}

impl<O: Observer, E: LaneExp, const N: usize, const D: usize, const EXTRAS: bool, const L: usize> pulp::WithSimd
    for PlainGroups<'_, '_, O, E, N, D, EXTRAS, L>
{
    type Output = Option<LaneRun>;

    #[inline(always)]
    fn with_simd<Sd: pulp::Simd>(self, _simd: Sd) -> Option<LaneRun> {
        let shape = self.tasks[0].model.shape();
        if !self.tasks.iter().all(|t| PlainLanes::<N, L, E>::accepts(t.model) && t.model.shape() == shape && t.model.layout.dim == D) {
            return Some(LaneRun::Fallback);
        }
        // the state stored component by component, lanes refilled from the queue
        Some(match *self.method {
            Method::Rk4 { dt } => {
                let ends = run_rk4_lanes::<O, E, N, D, EXTRAS, L>(self.tasks, dt, self.observer, self.cancel)?;
                LaneRun::Ran { ends: ends.into_iter().map(Some).collect(), handoffs: Vec::new() }
            }
            Method::Dopri5 { rtol, atol, first_step } | Method::Auto { rtol, atol, first_step } => {
                let auto = matches!(self.method, Method::Auto { .. });
                let mut handoffs = Vec::new();
                let ends = run_dopri5_lanes::<O, E, N, D, EXTRAS, L>(
                    self.tasks, rtol, atol, first_step, self.observer, self.cancel, auto, &mut handoffs,
                )?;
                LaneRun::Ran { ends, handoffs }
            }
            Method::Rodas4 { .. } => LaneRun::Fallback,
        })
    }
}

/// Run `tasks` of one fixed-size state layout (`N` nodes, `D` components, `EXTRAS`: lag states)
/// into `out`: on the vector lanes where they run there (`PlainGroups`, under `pulp`'s dispatch),
/// the runs that turned stiff then with the implicit method, `L` at a time; else `L` at a time
/// as lane-interleaved scalar code. `None` if cancelled.
fn run_fixed<O: Observer, E: LaneExp, const N: usize, const D: usize, const EXTRAS: bool, const L: usize>(
    tasks: &[Task],
    method: &Method,
    observer: &mut O,
    cancel: &AtomicBool,
    out: &mut Vec<(LaneEnd, Vec<f64>)>,
) -> Option<()> {
    // a vector step costs about what L/2 to L/3 lanes cost one by one, busy or not (measured:
    // three runs of a lag model on 8 lanes 1.07-1.36x their time one by one, nine 0.52x), so a
    // group that fills less than half its lanes runs lane by lane (the same bits either way)
    let run = if 2 * tasks.len() >= L {
        let groups = PlainGroups::<O, E, N, D, EXTRAS, L> { tasks, method, observer: &mut *observer, cancel, _exp: PhantomData };
        simd_arch().dispatch(groups)?
    } else {
        LaneRun::Fallback
    };
    match run {
        LaneRun::Ran { mut ends, handoffs } => {
            // lanes that turned stiff go on with the implicit method, L at a time
            for group in handoffs.chunks(L) {
                let chunk: Vec<Task> = group.iter().map(|h| Task { t_start: h.t, y0: &h.y, ..tasks[h.task] }).collect();
                let resume: Vec<Resume> = group.iter().map(|h| h.resume).collect();
                let index: Vec<usize> = group.iter().map(|h| h.task).collect();
                let mut done = Vec::with_capacity(group.len());
                run_group::<[f64; D], _, _, D, L>(
                    &chunk,
                    0,
                    method,
                    &Held::default(),
                    [0.0; D],
                    ModelRhs::<f64, N, EXTRAS, L>::for_tasks,
                    &mut Renumbered { inner: &mut *observer, index: &index },
                    cancel,
                    &mut done,
                    Some(&resume),
                )?;
                for (h, end) in group.iter().zip(done) {
                    ends[h.task] = Some(end);
                }
            }
            out.extend(ends.into_iter().map(|o| o.expect("every task ends")));
        }
        LaneRun::Fallback => {
            for (c, chunk) in tasks.chunks(L).enumerate() {
                run_group::<[f64; D], O, _, D, L>(
                    chunk,
                    c * L,
                    method,
                    &Held::default(),
                    [0.0; D],
                    ModelRhs::<f64, N, EXTRAS, L>::for_tasks,
                    observer,
                    cancel,
                    out,
                    None,
                )?;
            }
        }
    }
    Some(())
}

/// Run `tasks` (one state layout) with `method`, `L` at a time when their state is plain and of
/// a common size (register-resident, lane-interleaved), one at a time otherwise. The observer
/// sees task indices into `tasks`. Returns each task's end and final state; `None` if cancelled.
pub fn run_tasks<O: Observer, const L: usize>(
    tasks: &[Task],
    method: &Method,
    observer: &mut O,
    cancel: &AtomicBool,
) -> Option<Vec<(LaneEnd, Vec<f64>)>> {
    run_tasks_exp::<O, LibmExp, L>(tasks, method, observer, cancel)
}

/// [`run_tasks`] with the vector lanes' `exp` chosen by `E` (`LibmExp`: bitwise the scalar
/// model; `PolyExp`: vectorised, within 2 ulp per call).
pub fn run_tasks_exp<O: Observer, E: LaneExp, const L: usize>(
    tasks: &[Task],
    method: &Method,
    observer: &mut O,
    cancel: &AtomicBool,
) -> Option<Vec<(LaneEnd, Vec<f64>)>> {
    let mut out = Vec::with_capacity(tasks.len());
    if tasks.is_empty() {
        return Some(out);
    }
    // the plain models' lanes as vectors (lanes.rs), compiled for the processor's widest
    // vector instructions and chosen at run time (`simd_arch`)
    macro_rules! fixed {
        ($n:literal, $d:literal, $x:literal) => {
            run_fixed::<O, E, $n, $d, $x, L>(tasks, method, observer, cancel, &mut out)?
        };
    }
    // one state layout for the fixed-size path: every task's, when all have the same size
    let dim = tasks[0].model.layout.dim;
    let lags = tasks[0].model.lane_lags().filter(|_| tasks.iter().all(|t| t.model.layout.dim == dim && t.model.lane_lags().is_some()));
    with_state_size!(lags, tasks[0].model.layout.dof, fixed, {
        return run_tasks_one_by_one(tasks, method, &Held::default(), observer, cancel);
    });
    Some(out)
}

/// Run `tasks` one at a time on states of any size and any number type (dual numbers carry
/// derivatives through the same integrators). `held`: for an adaptive method, the steps to
/// take instead of choosing them (the steps another run accepted, see [`Held`]); empty for
/// none.
pub fn run_tasks_one_by_one<T: Scalar, O: Observer<T>>(
    tasks: &[Task<T>],
    method: &Method,
    held: &Held,
    observer: &mut O,
    cancel: &AtomicBool,
) -> Option<Vec<(LaneEnd, Vec<T>)>> {
    let mut out = Vec::with_capacity(tasks.len());
    for (c, task) in tasks.iter().enumerate() {
        let zero = vec![T::zero(); task.model.layout.dim];
        run_group::<Vec<T>, O, _, 0, 1>(
            std::slice::from_ref(task), c, method, held, zero,
            |c, slack| ModelRhs::<T, 0, true, 1>::for_tasks(c, slack),
            observer, cancel, &mut out, None,
        )?;
    }
    Some(out)
}
