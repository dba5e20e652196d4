//! Fixed-step RK4 over `L` plain models at once with the state stored component by component
//! (`y[j][i]`: component j of lane i), so every stage is vector arithmetic across the lanes
//! (`lanes/mod.rs`) and nothing is transposed but the one state the observer sees per accepted
//! step. A lane whose task finishes or diverges takes the next task from the queue at once, so
//! no lane idles while another point is still running (tasks of different lengths, retried or
//! diverging points).
//!
//! Per lane the arithmetic is that of `Rk4::step_lanes` on the scalar model, operation for
//! operation: with [`LibmExp`](crate::lanes::LibmExp) the results are bitwise those of
//! `run_tasks_one_by_one` (tested in `lanes/mod.rs`).

use std::sync::atomic::AtomicBool;

use crate::integrate::rk4::BOUND_SLACK;
use crate::integrate::tableau::{rk4_factor, rk4_sum, RK4_NODES};
use crate::integrate::task::{LaneEnd, Observer, Task};
use crate::lanes::{refill_lanes, LaneExp, PlainLanes, Queue};
use crate::physics::waveform::Cursor;

/// What one lane is running.
#[derive(Clone, Copy)]
struct Slot {
    task: usize,
    /// step index from t = 0 (step times are exact multiples of dt) and the last one
    k: usize,
    k_end: usize,
    cursor: Cursor,
    bound: f64,
    v_last: f64,
    steps: u64,
}

/// Run `tasks` (each accepted by [`PlainLanes::accepts`], `N` nodes, `D` = 2 N + 3 components
/// and the lag states, `EXTRAS` whether there are lag states)
/// with RK4 steps of `dt` [s], `L` lanes at a time, refilling lanes from the queue. The
/// observer sees task indices into `tasks`. Returns each task's end and final state, in task
/// order; `None` if cancelled. Always inlined: the caller compiles it for the processor's
/// vector width.
// Long: the lane driver's whole loop (stages, divergence, breakpoints, refill) is one inlined
// body compiled per instruction set, its state in fixed-size arrays kept in registers.
#[inline(always)]
pub fn run_rk4_lanes<O: Observer, E: LaneExp, const N: usize, const D: usize, const EXTRAS: bool, const L: usize>(
    tasks: &[Task],
    dt: f64,
    observer: &mut O,
    cancel: &AtomicBool,
) -> Option<Vec<(LaneEnd, Vec<f64>)>> {
    let mut out: Vec<Option<(LaneEnd, Vec<f64>)>> = vec![None; tasks.len()];
    if tasks.is_empty() {
        return Some(Vec::new());
    }
    let mut p = PlainLanes::<N, L, E>::new(&[tasks[0].model; L]).expect("tasks the vector path accepts");
    let mut y = [[0.0; L]; D];
    let mut slots: [Option<Slot>; L] = [None; L];
    let mut next = 0usize;
    let (mut k1, mut k2, mut k3, mut k4, mut tmp) = (
        [[0.0; L]; D],
        [[0.0; L]; D],
        [[0.0; L]; D],
        [[0.0; L]; D],
        [[0.0; L]; D],
    );
    let [c1, c2, c3, c4] = RK4_NODES.map(|c| c * dt);
    let factor = rk4_factor(dt);
    let mut lane_state = [0.0; D];
    let mut attempts = 0usize;
    loop {
        // refill idle lanes from the queue
        let queue = refill_lanes(
            tasks,
            &mut next,
            &mut slots,
            &mut p,
            &mut y,
            observer,
            &mut attempts,
            cancel,
            |_, t| {
                let task = &tasks[t];
                let k0 = (task.t_start / dt).round() as usize;
                Slot {
                    task: t,
                    k: k0,
                    k_end: k0 + ((task.t_end - task.t_start) / dt).round() as usize,
                    cursor: Cursor::at(task.wave, task.t_start),
                    bound: task.model.presliding_bound() * (1.0 + BOUND_SLACK) + 1e-12,
                    v_last: task.y0[task.model.layout.dof],
                    steps: 0,
                }
            },
        );
        match queue {
            Queue::Go => {}
            Queue::Done => break,
            Queue::Cancelled => return None,
        }
        // each lane's input over the step: V = v0 + slope tau (breakpoints on step boundaries)
        let (mut t0, mut v0, mut slope) = ([0.0; L], [0.0; L], [0.0; L]);
        for i in 0..L {
            if let Some(s) = &mut slots[i] {
                let wave = tasks[s.task].wave;
                t0[i] = s.k as f64 * dt;
                let probe = t0[i] + 0.5 * dt;
                s.cursor.advance(wave, probe);
                (v0[i], slope[i]) = s.cursor.input(wave, t0[i], probe);
            }
        }
        // plain loops, not array::from_fn: a call the compiler leaves out of line runs as
        // baseline code (see `Real::select`)
        let v_at = |tau: f64| -> [f64; L] {
            let mut v = v0;
            for i in 0..L {
                v[i] += slope[i] * tau;
            }
            v
        };
        let t_at = |tau: f64| -> [f64; L] {
            let mut t = t0;
            for x in t.iter_mut() {
                *x += tau;
            }
            t
        };
        // the four stages through one call site, so the right-hand side is inlined once
        let (mut ff, mut gdot) = ([0.0; L], [0.0; L]);
        for st in 0..4 {
            let tau = [c1, c2, c3, c4][st];
            let (src, dst) = match st {
                0 => (&y, &mut k1),
                1 => (&tmp, &mut k2),
                2 => (&tmp, &mut k3),
                _ => (&tmp, &mut k4),
            };
            let out = p.rhs_soa::<D, EXTRAS>(&t_at(tau), &v_at(tau), &slope, src, dst);
            match st {
                0 => {
                    (ff, gdot) = out;
                    stage(&mut tmp, &y, c2, &k1);
                }
                1 => stage(&mut tmp, &y, c3, &k2),
                2 => stage(&mut tmp, &y, c4, &k3),
                _ => {}
            }
        }
        for j in 0..D {
            for i in 0..L {
                y[j][i] += rk4_sum(k1[j][i], k2[j][i], k3[j][i], k4[j][i]) * factor;
            }
        }
        for i in 0..L {
            let Some(s) = &mut slots[i] else { continue };
            let task = &tasks[s.task];
            s.k += 1;
            let t_new = s.k as f64 * dt;
            for j in 0..D {
                lane_state[j] = y[j][i];
            }
            let model = task.model;
            let dof = model.layout.dof;
            if model.is_diverged(&lane_state, s.bound) {
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
            s.v_last = lane_state[dof];
            s.steps += 1;
            let done = s.k == s.k_end;
            observer.step(
                s.task,
                t_new,
                dt,
                &lane_state,
                v0[i] + slope[i] * dt,
                Some((ff[i], gdot[i])),
                done,
            );
            if done {
                out[s.task] = Some((
                    LaneEnd::Finished {
                        steps: s.steps,
                        min_step: dt,
                    },
                    lane_state.to_vec(),
                ));
                slots[i] = None;
            }
        }
    }
    Some(out.into_iter().map(|o| o.expect("every task ends")).collect())
}

/// tmp = y + h k, every component of every lane.
#[inline(always)]
fn stage<const D: usize, const L: usize>(tmp: &mut [[f64; L]; D], y: &[[f64; L]; D], h: f64, k: &[[f64; L]; D]) {
    for j in 0..D {
        for i in 0..L {
            tmp[j][i] = y[j][i] + k[j][i] * h;
        }
    }
}
