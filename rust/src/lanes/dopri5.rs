//! Dormand-Prince 5(4) over `L` plain models at once, the state stored component by component
//! (`y[j][i]`), each lane with its own step size, segment end and accept/reject decision
//! (masked updates), and lanes refilled from the queue as their tasks finish or fail. Per lane
//! the arithmetic is that of `integrate/dopri5.rs` driven by `drive/` operation for operation (the
//! stages, the error norm, the controller, first-same-as-last, landing on the input's
//! breakpoints), so results are bitwise those of the scalar path (tested in `lanes/mod.rs`).

use std::sync::atomic::AtomicBool;

use crate::integrate::crawl::CrawlWatch;
use crate::integrate::dopri5::{CONTROL, EXPLICIT_CRAWL_HINT};
use crate::integrate::stepper::{AdaptiveOptions, Attempt, Held};
use crate::integrate::stiffness::{h_lambda, StiffnessTest, TRY_IMPLICIT_AFTER};
use crate::integrate::tableau::{
    DP5_A2 as A2, DP5_A3 as A3, DP5_A4 as A4, DP5_A5 as A5, DP5_A6 as A6, DP5_B as B, DP5_C as C, DP5_E as E,
};
use crate::integrate::task::{adaptive_options, LaneEnd, Observer, Resume, Task};
use crate::lanes::{refill_lanes, LaneExp, PlainLanes, Queue};
use crate::physics::waveform::Cursor;

/// What one lane is running.
struct Slot {
    task: usize,
    t: f64,
    cursor: Cursor,
    opts: AdaptiveOptions,
    /// the step the lane tries next [s]
    h: f64,
    /// k0 must be evaluated anew (a new task, or the input's slope changed)
    fresh: bool,
    in_norm: f64,
    v_last: f64,
    steps: u64,
    min_step: f64,
    /// the pace of its last steps (`integrate/crawl.rs`)
    watch: CrawlWatch,
    test: StiffnessTest,
}

/// A lane of `method="auto"` that turned stiff: its task, state and what its run counted, to
/// be continued by `switching::Switching` from there, its trial step first.
pub struct Handoff {
    pub task: usize,
    pub t: f64,
    pub y: Vec<f64>,
    pub resume: Resume,
}

/// Each task's end and final state in task order, `None` for a task handed off.
type TaskEnds = Vec<Option<(LaneEnd, Vec<f64>)>>;

/// Run `tasks` (each accepted by [`PlainLanes::accepts`], `N` nodes, `D` = 2 N + 3 components
/// and the lag states, `EXTRAS` whether there are lag states)
/// with Dormand-Prince at tolerances `rtol`, `atol` from a first step `first_step` [s], `L`
/// lanes at a time, refilling lanes from the queue. Returns each task's end and final state in
/// task order; `None` if cancelled. With `auto`, Hairer's stiffness test runs on every
/// accepted step and a lane that switches (as `switching::Switching` decides) is not finished
/// here: its task's entry is `None` and it is listed in `handoffs`. Always inlined: the caller compiles it for the processor's
/// vector width.
// Long: the lane driver's whole loop (each lane's step, error norm, accept/reject, breakpoint
// landing, stiffness test, refill) is one inlined body compiled per instruction set; its state is
// fixed-size arrays the compiler keeps in registers, which helpers taking them by `&mut` would not.
#[inline(always)]
#[allow(clippy::too_many_arguments)]
// lane loops index several [f64; L] arrays by the same lane/component on purpose
#[allow(clippy::needless_range_loop)]
pub fn run_dopri5_lanes<
    O: Observer,
    E2: LaneExp,
    const N: usize,
    const D: usize,
    const EXTRAS: bool,
    const L: usize,
>(
    tasks: &[Task],
    rtol: f64,
    atol: f64,
    first_step: f64,
    observer: &mut O,
    cancel: &AtomicBool,
    auto: bool,
    handoffs: &mut Vec<Handoff>,
) -> Option<TaskEnds> {
    let mut out: TaskEnds = vec![None; tasks.len()];
    if tasks.is_empty() {
        return Some(Vec::new());
    }
    let mut p = PlainLanes::<N, L, E2>::new(&[tasks[0].model; L]).expect("tasks the vector path accepts");
    let mut slots: [Option<Slot>; L] = std::array::from_fn(|_| None);
    let mut y = [[0.0; L]; D];
    let mut k = [[[0.0; L]; D]; 7];
    let (mut tmp, mut y_new) = ([[0.0; L]; D], [[0.0; L]; D]);
    let mut scale = [[f64::INFINITY; L]; D];
    let mut lane_state = [0.0; D];
    let no_hold = Held::default();
    let mut next = 0usize;
    let mut attempts = 0usize;
    loop {
        let queue = refill_lanes(
            tasks,
            &mut next,
            &mut slots,
            &mut p,
            &mut y,
            observer,
            &mut attempts,
            cancel,
            |i, t| {
                let task = &tasks[t];
                let opts = adaptive_options(task, rtol, atol, first_step, &no_hold);
                for j in 0..D {
                    scale[j][i] = opts.scale[j];
                }
                Slot {
                    task: t,
                    t: task.t_start,
                    cursor: Cursor::at(task.wave, task.t_start),
                    h: opts.h_init.min(opts.h_max),
                    in_norm: opts.scale.iter().filter(|s| s.is_finite()).count().max(1) as f64,
                    opts,
                    fresh: true,
                    v_last: task.y0[task.model.layout.dof],
                    steps: 0,
                    min_step: f64::INFINITY,
                    watch: CrawlWatch::new(task.t_start),
                    test: StiffnessTest::default(),
                }
            },
        );
        match queue {
            Queue::Go => {}
            Queue::Done => break,
            Queue::Cancelled => return None,
        }
        // each lane's input, segment end and step (drive/, then Dopri5::attempt)
        let (mut t0, mut v0, mut slope, mut step) = ([0.0; L], [0.0; L], [0.0; L], [0.0; L]);
        let (mut end, mut last, mut fresh) = ([0.0; L], [false; L], [false; L]);
        for i in 0..L {
            let Some(s) = &mut slots[i] else { continue };
            let task = &tasks[s.task];
            if s.cursor.advance(task.wave, s.t) {
                s.fresh = true; // the input's slope changed
            }
            end[i] = s.cursor.next_breakpoint(task.wave, s.t).min(task.t_end);
            (v0[i], slope[i]) = s.cursor.input(task.wave, s.t, s.t);
            t0[i] = s.t;
            fresh[i] = s.fresh;
            s.fresh = false;
            let h = s.h;
            last[i] = end[i] - (s.t + h) < 1e-3 * h;
            step[i] = if last[i] { end[i] - s.t } else { h };
        }
        // plain loops, not array::from_fn (see lanes/rk4.rs)
        let v_at = |tau: &[f64; L]| -> [f64; L] {
            let mut v = v0;
            for i in 0..L {
                v[i] += slope[i] * tau[i];
            }
            v
        };
        let t_at = |tau: &[f64; L]| -> [f64; L] {
            let mut t = t0;
            for i in 0..L {
                t[i] += tau[i];
            }
            t
        };
        // the stages through one call site, so the right-hand side is inlined once (the first,
        // k0, only where a lane starts fresh; the last, k6, at the candidate: FSAL)
        let any_fresh = fresh.iter().any(|f| *f);
        let mut k0 = [[0.0; L]; D];
        for st in 0..7 {
            if st == 0 && !any_fresh {
                continue;
            }
            let (tau, src, dst): ([f64; L], &[[f64; L]; D], &mut [[f64; L]; D]) = match st {
                0 => ([0.0; L], &y, &mut k0),
                6 => {
                    combine(&mut y_new, &y, &step, &B, &k);
                    (step, &y_new, &mut k[6])
                }
                _ => {
                    let a: &[f64] = match st {
                        1 => &A2,
                        2 => &A3,
                        3 => &A4,
                        4 => &A5,
                        _ => &A6,
                    };
                    combine(&mut tmp, &y, &step, a, &k);
                    let mut tau = step;
                    for x in tau.iter_mut() {
                        *x *= C[st];
                    }
                    (tau, &tmp, &mut k[st])
                }
            };
            p.rhs_soa::<D, EXTRAS>(&t_at(&tau), &v_at(&tau), &slope, src, dst);
            if st == 0 {
                for j in 0..D {
                    for i in 0..L {
                        if fresh[i] {
                            k[0][j][i] = k0[j][i];
                        }
                    }
                }
            }
        }
        let err = error_norms(&y, &y_new, &k, &scale, &step, rtol, atol);
        for i in 0..L {
            let Some(s) = &mut slots[i] else { continue };
            let err = err[i] / s.in_norm;
            let err = err.sqrt();
            let mut stiff = false;
            let attempt = if err <= 1.0 {
                if auto {
                    let hl = h_lambda(
                        step[i],
                        D,
                        |c| scale[c][i],
                        |c| tmp[c][i],
                        |c| k[5][c][i],
                        |c| y_new[c][i],
                        |c| k[6][c][i],
                    );
                    stiff = s.test.observe(hl, TRY_IMPLICIT_AFTER);
                }
                for j in 0..D {
                    y[j][i] = y_new[j][i];
                    k[0][j][i] = k[6][j][i]; // first same as last
                }
                s.h = CONTROL.after_accept(err, step[i], last[i], s.h, &s.opts);
                Attempt::Accepted {
                    step: step[i],
                    last: last[i],
                }
            } else {
                let (h, outcome) = CONTROL.after_reject(err, step[i], &s.opts);
                s.h = h;
                outcome
            };
            let task = &tasks[s.task];
            for j in 0..D {
                lane_state[j] = y[j][i];
            }
            match attempt {
                Attempt::Accepted { step, last } => {
                    let t_new = if last { end[i] } else { s.t + step };
                    let span = t_new - s.t;
                    let done = t_new >= task.t_end;
                    s.t = t_new;
                    if task.model.is_diverged(&lane_state, f64::INFINITY) {
                        out[s.task] = Some((
                            LaneEnd::Diverged {
                                t: t_new,
                                why: None,
                                v_last: s.v_last,
                            },
                            lane_state.to_vec(),
                        ));
                        slots[i] = None;
                        continue;
                    }
                    s.v_last = lane_state[task.model.layout.dof];
                    s.steps += 1;
                    s.min_step = s.min_step.min(span);
                    if !done {
                        // as the scalar path (`drive/`): a collapsed step stops the run
                        if let Some(why) = s.watch.observe(s.steps, t_new, task.t_end, EXPLICIT_CRAWL_HINT) {
                            out[s.task] = Some((
                                LaneEnd::Diverged {
                                    t: t_new,
                                    why: Some(why),
                                    v_last: s.v_last,
                                },
                                lane_state.to_vec(),
                            ));
                            slots[i] = None;
                            continue;
                        }
                    }
                    observer.accepted_step(s.task, step);
                    observer.step(s.task, t_new, span, &lane_state, v0[i] + slope[i] * step, None, done);
                    if done {
                        out[s.task] = Some((
                            LaneEnd::Finished {
                                steps: s.steps,
                                min_step: s.min_step,
                            },
                            lane_state.to_vec(),
                        ));
                        slots[i] = None;
                    } else if stiff {
                        let resume = Resume {
                            steps: s.steps,
                            min_step: s.min_step,
                            v_last: s.v_last,
                            h: s.h,
                            watch: s.watch,
                        };
                        handoffs.push(Handoff {
                            task: s.task,
                            t: t_new,
                            y: lane_state.to_vec(),
                            resume,
                        });
                        slots[i] = None;
                    }
                }
                Attempt::Failed(why) => {
                    out[s.task] = Some((
                        LaneEnd::Diverged {
                            t: s.t,
                            why: Some(why),
                            v_last: s.v_last,
                        },
                        lane_state.to_vec(),
                    ));
                    slots[i] = None;
                }
                _ => {}
            }
        }
    }
    Some(out)
}

/// out = y + step sum_j a_j k_j, per lane (as `dopri5::combine`).
#[inline(always)]
fn combine<const D: usize, const L: usize>(
    out: &mut [[f64; L]; D],
    y: &[[f64; L]; D],
    step: &[f64; L],
    a: &[f64],
    k: &[[[f64; L]; D]; 7],
) {
    for c in 0..D {
        for i in 0..L {
            let mut s = 0.0;
            for (j, aj) in a.iter().enumerate() {
                s += k[j][c][i] * *aj;
            }
            out[c][i] = y[c][i] + s * step[i];
        }
    }
}

/// Each lane's sum of squared scaled errors (as `Dopri5::error_norm` before its division by
/// the component count and square root).
#[inline(always)]
fn error_norms<const D: usize, const L: usize>(
    y: &[[f64; L]; D],
    y_new: &[[f64; L]; D],
    k: &[[[f64; L]; D]; 7],
    scale: &[[f64; L]; D],
    step: &[f64; L],
    rtol: f64,
    atol: f64,
) -> [f64; L] {
    let mut err2 = [0.0; L];
    for c in 0..D {
        for i in 0..L {
            if scale[c][i].is_finite() {
                let mut e = 0.0;
                for (j, ej) in E.iter().enumerate() {
                    e += ej * k[j][c][i];
                }
                let tol = atol * scale[c][i] + rtol * y[c][i].abs().max(y_new[c][i].abs());
                err2[i] += (step[i] * e / tol).powi(2);
            }
        }
    }
    err2
}
