//! Running a batch: points checked, grouped into lanes of one state layout, driven, retried at a
//! smaller step when RK4 diverges, in parallel over rayon's pool.

use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};

use rayon::prelude::*;

use crate::drive::run_tasks;
use crate::integrate::method::Method;
use crate::integrate::plan::check_task;
use crate::integrate::stepper::Held;
use crate::integrate::task::{LaneEnd, SimError, Task};
use crate::model::Model;
use crate::sensitivity::{derivatives, parse_seeds, Schedule};

use super::metrics::{MetricsObserver, PointMetrics};
use super::{BatchConfig, PointOutput, PointSpec, Status};

/// Points advanced together per core (see `integrate/stepper.rs` and `lanes/rk4.rs`): eight f64 lanes fill
/// two AVX2 registers per quantity; the choice is measured in `benches/lanes_cost.rs`.
pub const LANES: usize = 8;

/// Points per rayon task: the queue one lane group refills its lanes from. Eight lane-fulls:
/// a lane whose point ends takes the next point of the queue rather than idling until the
/// slowest of its group ends, and the points that `method="auto"` hands to the implicit method
/// gather into fuller groups (their stages run as vectors only where half the lanes are busy).
/// A task is tens of milliseconds or more, so scheduling costs nothing; a batch with few points
/// (a fit's Jacobian) is split finer (`chunk_size`). Results do not depend on it (every point
/// runs alone, bitwise, on lanes or not).
pub const CHUNK: usize = 8 * LANES;

/// A point that passed its checks: model, initial state and planned RK4 steps (0 if adaptive).
struct Ready<'a> {
    index: usize,
    spec: &'a PointSpec,
    model: Model,
    y0: Vec<f64>,
    steps: usize,
}

fn prepare<'a>(cfg: &BatchConfig, index: usize, spec: &'a PointSpec) -> Result<Ready<'a>, String> {
    let model = Model::new(spec.params, spec.effects, cfg.structure, cfg.piezo_hysteresis, false)?;
    let y0 = spec.y0.clone().unwrap_or_else(|| model.rest_state());
    let (t_start, t_end) = (spec.t_start, spec.t_end(cfg));
    let task = Task {
        model: &model,
        wave: &spec.wave,
        t_start,
        t_end,
        y0: &y0,
    };
    check_task(&task, &cfg.method).map_err(|e| e.to_string())?;
    let steps = cfg
        .method
        .fixed_step()
        .map_or(0, |dt| ((t_end - t_start) / dt).round() as usize);
    Ok(Ready {
        index,
        spec,
        model,
        y0,
        steps,
    })
}

/// Where and why a point's run failed.
struct Failure {
    /// [s]
    t: f64,
    /// the method's own account (an adaptive step that collapsed: `integrate/crawl.rs`), if it gave one
    why: Option<String>,
}

/// Drive a lane group with `method`. `Err` marks a point that diverged (the caller may retry
/// it); `None` if cancelled.
fn run_group(
    cfg: &BatchConfig,
    method: &Method,
    record_every: usize,
    group: &[&Ready],
    cancel: &AtomicBool,
) -> Option<Vec<Result<PointOutput, Failure>>> {
    let tasks: Vec<Task> = group
        .iter()
        .map(|r| Task {
            model: &r.model,
            wave: &r.spec.wave,
            t_start: r.spec.t_start,
            t_end: r.spec.t_end(cfg),
            y0: &r.y0,
        })
        .collect();
    let steps: Vec<usize> = group.iter().map(|r| r.steps).collect();
    let trains: Vec<_> = group
        .iter()
        .map(|r| (r.spec.train, r.model.params.d33 * r.spec.wave.peak()))
        .collect();
    let mut obs = MetricsObserver::new(
        group.iter().map(|r| &r.model).collect(),
        record_every,
        &steps,
        &trains,
        cfg.skip_cycles,
    );
    let ends = run_tasks::<_, LANES>(&tasks, method, &mut obs, cancel)?;
    Some(
        ends.into_iter()
            .enumerate()
            .map(|(i, (end, y))| match end {
                LaneEnd::Finished { steps, min_step } if y.iter().all(|x| x.is_finite()) => {
                    let (duration, dt_used) = match method.fixed_step() {
                        // the planned duration, as a whole number of steps
                        Some(dt) => (steps as f64 * dt, dt),
                        None => (tasks[i].t_end - tasks[i].t_start, min_step),
                    };
                    Ok(PointOutput {
                        metrics: obs.finish(i, &y, duration, dt_used, steps),
                        trace: std::mem::take(&mut obs.traces[i]),
                        final_state: if cfg.final_states { y } else { Vec::new() },
                        sensitivities: Vec::new(),
                        reason: String::new(),
                    })
                }
                LaneEnd::Finished { .. } => Err(Failure {
                    t: tasks[i].t_end,
                    why: None,
                }),
                LaneEnd::Diverged { t, why, .. } => Err(Failure { t, why }),
            })
            .collect(),
    )
}

/// What each diverged point of a lane group reports after its retries (if any) at RK4 steps
/// dt/2, dt/4, ... (recording at the same times), in the order of `failed`. The points that
/// diverge again are retried together, on lanes as they first ran: a lane's arithmetic is that
/// of the point run alone, so the outputs are those of one retry per point, at a fraction of
/// the time where many points of a batch need a smaller step. `None` where cancelled.
fn retry_group(cfg: &BatchConfig, failed: Vec<(&Ready, Failure)>, cancel: &AtomicBool) -> Vec<Option<PointOutput>> {
    let (mut method, mut record_every) = (cfg.method, cfg.record_every);
    let first_step = method.first_step();
    let mut dt_tried = vec![first_step; failed.len()];
    let mut failed_at: Vec<f64> = failed.iter().map(|(_, f)| f.t).collect();
    let mut out: Vec<Option<PointOutput>> = vec![None; failed.len()];
    // the points still to be retried (indices into `failed`)
    let mut pending: Vec<usize> = (0..failed.len()).collect();
    if let Some(mut dt) = cfg.method.fixed_step() {
        for _ in 0..cfg.retries {
            if pending.is_empty() {
                break;
            }
            dt /= 2.0;
            record_every *= 2;
            // the method asked, at the smaller step
            method = cfg.method.with_step(dt).expect("a fixed-step method");
            let mut runs: Vec<(usize, Ready)> = Vec::with_capacity(pending.len());
            for &i in &pending {
                let ready = failed[i].0;
                dt_tried[i] = dt;
                // a point whose run cannot be planned at this step stops retrying here
                if let Ok(steps) = crate::integrate::plan::plan_steps(
                    &ready.model,
                    &ready.spec.wave,
                    ready.spec.t_start,
                    ready.spec.t_end(cfg),
                    dt,
                ) {
                    let r = Ready {
                        steps,
                        y0: ready.y0.clone(),
                        model: ready.model.clone(),
                        ..*ready
                    };
                    runs.push((i, r));
                }
            }
            if runs.is_empty() {
                break;
            }
            let group: Vec<&Ready> = runs.iter().map(|(_, r)| r).collect();
            let Some(results) = run_group(cfg, &method, record_every, &group, cancel) else {
                return out; // cancelled: the points not finished stay None
            };
            pending.clear();
            for ((i, _), res) in runs.iter().zip(results) {
                match res {
                    Ok(o) => {
                        let first_failure = failed[*i].1.t;
                        out[*i] = Some(PointOutput {
                            metrics: PointMetrics {
                                status: Status::Retried,
                                ..o.metrics
                            },
                            reason: format!(
                                "diverged at t = {first_failure:.6e} s with dt = {first_step:e} s; finished at dt = {dt:e} s"
                            ),
                            ..o
                        });
                    }
                    Err(f) => {
                        failed_at[*i] = f.t;
                        pending.push(*i);
                    }
                }
            }
        }
    }
    for (i, (_, first)) in failed.iter().enumerate() {
        if out[i].is_some() {
            continue;
        }
        let how = match &first.why {
            _ if cfg.method.is_fixed() => format!("at every step tried (down to dt = {:e} s)", dt_tried[i]),
            Some(why) => format!("({why})"),
            None => "(the adaptive step collapsed or the state left its bounds)".to_string(),
        };
        out[i] = Some(PointOutput {
            metrics: PointMetrics::diverged(failed_at[i], dt_tried[i]),
            trace: Vec::new(),
            final_state: Vec::new(),
            sensitivities: Vec::new(),
            reason: format!("diverged at t = {:.6e} s {how}", failed_at[i]),
        });
    }
    out
}

/// Add the derivatives of a finished point's recorded readings (at the RK4 step it finished
/// with, a retry's included) with respect to the batch's sensitivity names; a point whose
/// names cannot be differentiated becomes invalid with the reason. `None` if cancelled.
fn add_sensitivities(
    cfg: &BatchConfig,
    ready: &Ready,
    mut out: PointOutput,
    cancel: &AtomicBool,
) -> Option<PointOutput> {
    if cfg.sensitivities.is_empty() || !matches!(out.metrics.status, Status::Ok | Status::Retried) {
        return Some(out);
    }
    let seeds = match parse_seeds(&ready.model, &cfg.sensitivities, ready.spec.normal_force_derived) {
        Ok(s) => s,
        Err(why) => return Some(PointOutput::invalid(why.into())),
    };
    let (Some(dt), dt_used) = (cfg.method.fixed_step(), out.metrics.dt_used) else {
        return Some(out); // refused by BatchConfig::validate
    };
    // a retry halves the step and doubles the steps between recorded readings
    let every = cfg.record_every * (dt / dt_used).round().max(1.0) as usize;
    let schedule = Schedule {
        every,
        also_last: false,
    };
    // the method asked, at the step the run used (a retry's)
    let Some(method) = cfg.method.with_step(dt_used) else {
        return Some(out);
    };
    let (t_start, t_end) = (ready.spec.t_start, ready.spec.t_end(cfg));
    let held = Held::default();
    let d = derivatives(
        &ready.model,
        &ready.spec.wave,
        t_start,
        t_end,
        &ready.y0,
        &method,
        &held,
        schedule,
        &seeds,
        ready.spec.normal_force_derived,
        cancel,
    )?;
    match d {
        Ok(d) => {
            let (n, nt) = (d.names, d.readings.len() / d.names.max(1));
            // [time][name] -> [name][time]
            out.sensitivities = (0..n * nt).map(|k| d.readings[(k % nt) * n + k / nt]).collect();
            Some(out)
        }
        Err(e) => {
            // the readings stand; their derivatives do not, and the reason says why
            out.sensitivities = vec![f64::NAN; seeds.len() * out.trace.len()];
            out.reason = format!("sensitivities: {e}");
            Some(out)
        }
    }
}

/// The derivative passes of `valid` points whose plain run the caller already has
/// (`BatchConfig::derivatives_only`): each as [`add_sensitivities`] takes them after a run that
/// finished at the configured step, without that run. A pass that fails leaves its point
/// without derivatives (empty: there is no trace to size them by) and says why in its reason.
fn derivatives_alone(
    cfg: &BatchConfig,
    valid: &[Ready],
    cancel: &AtomicBool,
    done: &AtomicUsize,
    out: &mut [Option<PointOutput>],
) {
    let Some(dt) = cfg.method.fixed_step() else {
        return; // refused by BatchConfig::validate
    };
    for r in valid {
        if cancel.load(Ordering::Relaxed) {
            break;
        }
        let ran = PointOutput {
            metrics: PointMetrics {
                dt_used: dt,
                steps: r.steps as u64,
                ..PointMetrics::with_status(Status::Ok)
            },
            ..PointOutput::with_status(Status::Ok)
        };
        let res = add_sensitivities(cfg, r, ran, cancel);
        if res.is_some() {
            done.fetch_add(1, Ordering::Relaxed);
        }
        out[r.index] = res;
    }
}

/// End of the lane group starting at `start`: up to CHUNK points sharing one state layout.
fn lane_group_end(valid: &[Ready], start: usize) -> usize {
    let dim = valid[start].model.layout.dim;
    let mut end = start + 1;
    while end < valid.len() && end - start < CHUNK && valid[end].model.layout.dim == dim {
        end += 1;
    }
    end
}

/// Run one chunk of points (any size); `None` entries were cancelled before finishing.
fn run_chunk(
    cfg: &BatchConfig,
    specs: &[&PointSpec],
    cancel: &AtomicBool,
    done: &AtomicUsize,
) -> Vec<Option<PointOutput>> {
    let mut out: Vec<Option<PointOutput>> = vec![None; specs.len()];
    // invalid points are answered at once; valid ones are grouped by layout for the lanes
    let mut valid: Vec<Ready> = Vec::with_capacity(specs.len());
    for (i, s) in specs.iter().enumerate() {
        match prepare(cfg, i, s) {
            Ok(r) => valid.push(r),
            Err(why) => {
                out[i] = Some(PointOutput::invalid(why));
                done.fetch_add(1, Ordering::Relaxed);
            }
        }
    }
    if cfg.derivatives_only {
        derivatives_alone(cfg, &valid, cancel, done, &mut out);
        return out;
    }
    let mut start = 0;
    while start < valid.len() {
        if cancel.load(Ordering::Relaxed) {
            break;
        }
        let end = lane_group_end(&valid, start);
        let group: Vec<&Ready> = valid[start..end].iter().collect();
        let Some(results) = run_group(cfg, &cfg.method, cfg.record_every, &group, cancel) else {
            break; // cancelled
        };
        let mut finished: Vec<(&Ready, Option<PointOutput>)> = Vec::with_capacity(group.len());
        let mut failed: Vec<(&Ready, Failure)> = Vec::new();
        for (r, res) in group.iter().zip(results) {
            match res {
                Ok(x) => finished.push((r, Some(x))),
                Err(f) => failed.push((r, f)),
            }
        }
        let retried: Vec<&Ready> = failed.iter().map(|(r, _)| *r).collect();
        finished.extend(retried.into_iter().zip(retry_group(cfg, failed, cancel)));
        for (r, res) in finished {
            let res = res.and_then(|o| add_sensitivities(cfg, r, o, cancel));
            if res.is_some() {
                done.fetch_add(1, Ordering::Relaxed);
            }
            out[r.index] = res;
        }
        start = end;
    }
    out
}

/// Points per rayon task for a batch of `n` points on `threads` threads: about an eighth of a
/// thread's share, so that the threads end together when points differ in cost (a sweep's
/// corners take 10x its middle), between a lane group ([`LANES`]) and [`CHUNK`] points; fewer
/// when the batch has fewer than a group per thread, so that every thread gets some (a fit's
/// prediction of one model on three experiments is three points: one task of three would leave
/// the other threads idle). Grouping changes no result (every point runs alone, bitwise, on
/// lanes or not).
fn chunk_size(n: usize, threads: usize) -> usize {
    let threads = threads.max(1);
    (n / (8 * threads)).clamp(LANES, CHUNK).min(n.div_ceil(threads)).max(1)
}

/// Run every point on the current rayon pool. Unfinished points (after `cancel`) come back as
/// `Status::NotRun` with NaN metrics; `done` counts finished points as they finish.
pub fn run_batch(
    cfg: &BatchConfig,
    specs: &[PointSpec],
    cancel: &AtomicBool,
    done: &AtomicUsize,
) -> Result<Vec<PointOutput>, SimError> {
    cfg.validate().map_err(SimError::from)?;
    let threads = rayon::current_num_threads();
    let size = chunk_size(specs.len(), threads);
    let outputs: Vec<Option<PointOutput>> = if threads > 1 && specs.len() > 1 && 2 * size < LANES {
        // every task runs its points lane by lane, so a task costs the sum of its points'
        // durations: tasks balanced by duration (a fit's prediction of experiments 44, 19, 54
        // and 104 ms long: [44, 19] and [54, 104] in order, [104] and [44, 19, 54] balanced)
        let bins = balanced(&durations(cfg, specs), threads);
        let mut ran: Vec<(usize, Option<PointOutput>)> = bins
            .par_iter()
            .flat_map_iter(|bin| {
                let chunk: Vec<&PointSpec> = bin.iter().map(|&i| &specs[i]).collect();
                bin.iter().copied().zip(run_chunk(cfg, &chunk, cancel, done))
            })
            .collect();
        ran.sort_by_key(|(i, _)| *i);
        ran.into_iter().map(|(_, o)| o).collect()
    } else {
        specs
            .par_chunks(size)
            .flat_map_iter(|chunk| run_chunk(cfg, &chunk.iter().collect::<Vec<_>>(), cancel, done))
            .collect()
    };
    Ok(outputs
        .into_iter()
        .map(|m| m.unwrap_or_else(|| PointOutput::with_status(Status::NotRun)))
        .collect())
}

/// Each point's simulated span [s], the measure of its cost when it runs alone.
fn durations(cfg: &BatchConfig, specs: &[PointSpec]) -> Vec<f64> {
    specs.iter().map(|s| s.t_end(cfg) - s.t_start).collect()
}

/// `costs`' indices in `bins` bins of about equal total cost: the longest first, each into the
/// bin with the least so far (the LPT rule, within 4/3 of the best split); each bin's indices
/// ascending, empty bins left out.
fn balanced(costs: &[f64], bins: usize) -> Vec<Vec<usize>> {
    let mut order: Vec<usize> = (0..costs.len()).collect();
    order.sort_by(|&a, &b| costs[b].total_cmp(&costs[a]).then(a.cmp(&b)));
    let mut out: Vec<(f64, Vec<usize>)> = vec![(0.0, Vec::new()); bins.max(1)];
    for i in order {
        let least = (0..out.len())
            .min_by(|&a, &b| out[a].0.total_cmp(&out[b].0).then(a.cmp(&b)))
            .unwrap_or(0);
        out[least].0 += costs[i].max(0.0);
        out[least].1.push(i);
    }
    out.into_iter()
        .filter(|(_, b)| !b.is_empty())
        .map(|(_, mut b)| {
            b.sort_unstable();
            b
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn batches_are_split_about_eight_tasks_per_thread_between_a_lane_group_and_a_chunk() {
        assert_eq!(chunk_size(3, 2), 2); // [2, 1]: both threads busy
        assert_eq!(chunk_size(9, 2), 5); // [5, 4] rather than [8, 1]
        assert_eq!(chunk_size(256, 2), 16); // eight tasks per thread
        assert_eq!(chunk_size(1_000_000, 2), CHUNK);
        assert_eq!(chunk_size(200, 16), LANES); // at least a lane group
        assert_eq!(chunk_size(100, 16), 7); // but every thread gets some
        assert_eq!(chunk_size(5, 1), 5);
        assert_eq!(chunk_size(0, 2), 1); // par_chunks needs a positive size
    }

    #[test]
    fn small_batches_are_balanced_by_duration() {
        // a fit's four experiments: in order [44, 19] and [54, 104]; balanced [104], [44, 19, 54]
        assert_eq!(balanced(&[44.0, 19.0, 54.0, 104.0], 2), vec![vec![3], vec![0, 1, 2]]);
        // three experiments 52, 32, 22: [52], [32, 22] rather than [52, 32], [22]
        assert_eq!(balanced(&[52.0, 32.0, 22.0], 2), vec![vec![0], vec![1, 2]]);
        // equal spans: alternate, every bin used
        assert_eq!(balanced(&[1.0; 4], 2), vec![vec![0, 2], vec![1, 3]]);
        // fewer points than bins: no empty bin
        assert_eq!(balanced(&[3.0], 4), vec![vec![0]]);
        assert!(balanced(&[], 2).is_empty());
    }
}
