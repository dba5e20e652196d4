//! The one driver every run goes through, single trajectories and batch points alike: it plans
//! the steps, walks the input's breakpoints, sets each lane's input for the step, asks the
//! integrator ([`Stepper`]) to attempt it, checks the model's divergence criterion, and hands
//! every accepted state to an [`Observer`] (saving a trajectory, recording sensor readings,
//! accumulating sweep metrics are observers).
//!
//! Up to `L` runs ("lanes") of one state layout advance together, stage by stage (see
//! `integrate/stepper.rs`); a lane's arithmetic is exactly that of a run alone, so results do not depend on
//! how runs are grouped.

use std::sync::atomic::{AtomicBool, Ordering};

use crate::integrate::crawl::CrawlWatch;
use crate::integrate::dopri5::Dopri5;
use crate::integrate::method::Method;
use crate::integrate::model_rhs::{LaneInputs, ModelRhs};
use crate::integrate::rk4::Rk4;
use crate::integrate::rodas4::Rodas4;
use crate::integrate::stepper::{AdaptiveOptions, Attempt, Held, State, Stepper};
use crate::integrate::switching::Switching;
use crate::integrate::task::{adaptive_options, LaneEnd, Observer, Resume, Task, CANCEL_CHECK_ATTEMPTS};
use crate::lanes::{LaneExp, LibmExp};
use crate::model::with_state_size;
use crate::numbers::scalar::Scalar;
use crate::physics::waveform::Cursor;

mod lane_groups;
use lane_groups::run_fixed;

/// Advance up to `L` tasks of one state layout together (`tasks[i]` on lane i; unused lanes idle)
/// from their initial states in `ys`, which end holding the final states, with `rhs` their
/// right-hand side (see [`ModelRhs::for_tasks`]). `first` is the index the observer sees for
/// lane 0; `dt` [s] the step of a fixed-step stepper; `resume`: tasks that continue a run
/// (their observer was started already, their counts go on). `None` if cancelled. Always
/// inlined: the caller may compile it for the processor's vector width (`run_tasks`).
// Long: one step loop whose per-lane state (input cursor, step, counts, crawl watch) stays in
// locals across the attempt, the divergence check and the observer; split, each part would take a
// dozen `&mut` arguments and lose the guaranteed inlining the vector dispatch needs.
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
    let bound: [f64; L] = std::array::from_fn(|i| tasks[lane(i)].model.presliding_bound() * (1.0 + slack) + 1e-12);
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
            Some(r) => {
                (steps[i], min_step[i], v_last[i], watch[i]) = (r[i].steps, r[i].min_step, r[i].v_last, r[i].watch)
            }
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
                    out[i] = Some(LaneEnd::Diverged {
                        t: t_new,
                        why: Some(why),
                        v_last: v_last[i],
                    });
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
    Some(out.into_iter().map(|o| o.expect("every lane ends")).collect())
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
    let opts = |rtol, atol, first_step| group_options(chunk, rtol, atol, first_step, held);
    match *method {
        Method::Rk4 { dt } => {
            let st: Rk4<S, L> = Rk4::new(dt, zero.clone());
            drive_group(chunk, first, dt, st, zero, rhs_for, observer, cancel, out, resume)
        }
        Method::Dopri5 { rtol, atol, first_step } => {
            let st: Dopri5<S, L> = Dopri5::new(opts(rtol, atol, first_step), zero.clone());
            drive_group(chunk, first, 0.0, st, zero, rhs_for, observer, cancel, out, resume)
        }
        Method::Rodas4 { rtol, atol, first_step } => {
            let st: Rodas4<S, L, D> = Rodas4::new(opts(rtol, atol, first_step), zero.clone());
            drive_group(chunk, first, 0.0, st, zero, rhs_for, observer, cancel, out, resume)
        }
        Method::Auto { rtol, atol, first_step } => {
            let st = switching::<S, D, L>(opts(rtol, atol, first_step), zero.clone(), resume);
            drive_group(chunk, first, 0.0, st, zero, rhs_for, observer, cancel, out, resume)
        }
    }
}

/// Each lane's adaptive options for a group of tasks (idle lanes take the last task's).
#[inline(always)]
fn group_options<T: Scalar, const L: usize>(
    chunk: &[Task<T>],
    rtol: f64,
    atol: f64,
    first_step: f64,
    held: &Held,
) -> [AdaptiveOptions; L] {
    std::array::from_fn(|i| adaptive_options(&chunk[i.min(chunk.len() - 1)], rtol, atol, first_step, held))
}

/// `method="auto"`'s stepper for a group; runs handed over from the vector lanes (`resume`)
/// start with their Rodas4 trial pending.
#[inline(always)]
fn switching<S: State, const D: usize, const L: usize>(
    opts: [AdaptiveOptions; L],
    zero: S,
    resume: Option<&[Resume]>,
) -> Switching<S, L, D> {
    let mut st: Switching<S, L, D> = Switching::new(opts, zero);
    if let Some(r) = resume {
        for (i, r) in r.iter().enumerate() {
            st.start_trial(i, r.h, r.steps);
        }
    }
    st
}

/// Drive one group of up to `L` tasks with stepper `st` (see [`run_group`]).
#[allow(clippy::too_many_arguments)]
#[inline(always)]
fn drive_group<'a, S, St, O, R, const L: usize>(
    chunk: &[Task<'a, S::Elem>],
    first: usize,
    dt: f64,
    mut st: St,
    zero: S,
    rhs_for: impl FnOnce(&[Task<'a, S::Elem>], f64) -> R,
    observer: &mut O,
    cancel: &AtomicBool,
    out: &mut Vec<(LaneEnd, Vec<S::Elem>)>,
    resume: Option<&[Resume]>,
) -> Option<()>
where
    S: State,
    St: Stepper<S, L>,
    O: Observer<S::Elem>,
    R: LaneInputs<S::Elem, L>,
{
    let task = |i: usize| &chunk[i.min(chunk.len() - 1)];
    let mut ys: [S; L] = std::array::from_fn(|i| {
        let mut y = zero.clone();
        y.as_mut().copy_from_slice(task(i).y0);
        y
    });
    let mut rhs = rhs_for(chunk, st.admissible_slack());
    let ends = drive_lanes(chunk, first, dt, &mut st, &mut rhs, &mut ys, observer, cancel, resume)?;
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
    // the plain models' lanes as vectors (lanes/mod.rs), compiled for the processor's widest
    // vector instructions and chosen at run time (`simd_arch`)
    macro_rules! fixed {
        ($n:literal, $d:literal, $x:literal) => {
            run_fixed::<O, E, $n, $d, $x, L>(tasks, method, observer, cancel, &mut out)?
        };
    }
    // one state layout for the fixed-size path: every task's, when all have the same size
    let dim = tasks[0].model.layout.dim;
    let lags = tasks[0].model.lane_lags().filter(|_| {
        tasks
            .iter()
            .all(|t| t.model.layout.dim == dim && t.model.lane_lags().is_some())
    });
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
            std::slice::from_ref(task),
            c,
            method,
            held,
            zero,
            |c, slack| ModelRhs::<T, 0, true, 1>::for_tasks(c, slack),
            observer,
            cancel,
            &mut out,
            None,
        )?;
    }
    Some(out)
}
