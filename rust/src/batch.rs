//! The batch engine behind sweeps: many independent points (parameters, effects, waveform),
//! each reduced to a few metrics inside the loop — no trajectory is stored, so memory is
//! O(points x metrics). Points run in parallel with rayon; with RK4, groups of `LANES` points
//! advance stage by stage together (see rk4.rs) so one core works on several independent
//! dependency chains at once. Every point's arithmetic is exactly that of `simulate` for the
//! same settings, so results do not depend on thread count, chunking or lane grouping.

use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};

use rayon::prelude::*;

use crate::dopri5::{self, Dopri5Options};
use crate::effects::Effects;
use crate::mechanics::Structure;
use crate::model::{with_state_size, Model};
use crate::params::Params;
use crate::rk4::{Rhs, Rk4};
use crate::simulate::{plan_steps, rest_state, ModelRhs, SimError};
use crate::waveform::PiecewiseLinear;

/// Points advanced together per core with RK4.
pub const LANES: usize = 4;
/// The main body counts as sliding when |v1| exceeds this share of the Stribeck velocity:
/// presliding (elastic asperity) motion is orders of magnitude slower.
pub const SLIP_VELOCITY_FACTOR: f64 = 0.1;
/// How often (in steps) a running point looks at the cancel flag.
const CANCEL_CHECK_STEPS: usize = 1 << 14;

/// Integration method for a batch.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Method {
    /// Fixed-step classical RK4 with step `BatchConfig::dt` (the reference).
    Rk4,
    /// Adaptive Dormand-Prince 5(4); `BatchConfig::dt` is the first trial step.
    Dopri5 { rtol: f64, atol: f64 },
}

/// What is common to every point of a batch.
#[derive(Clone, Copy, Debug)]
pub struct BatchConfig {
    pub structure: Structure,
    pub piezo_hysteresis: bool,
    pub t_end: f64,
    pub dt: f64,
    pub method: Method,
    /// RK4: on divergence, retry with dt/2, dt/4, ... this many times before flagging the point
    pub retries: u32,
    /// RK4: record the sensor reading at t = 0 and every `record_every` steps (0: none). The
    /// only per-time output of a batch; fits compare it with recordings.
    pub record_every: usize,
}

/// One point: its parameters, effects, input and the number of drive cycles (0 if not a train).
#[derive(Clone, Debug)]
pub struct PointSpec {
    pub params: Params,
    pub effects: Effects,
    pub wave: PiecewiseLinear,
    pub cycles: usize,
    /// this point's duration [s] if it differs from the batch's `t_end`
    pub t_end: Option<f64>,
}

impl PointSpec {
    fn t_end(&self, cfg: &BatchConfig) -> f64 {
        self.t_end.unwrap_or(cfg.t_end)
    }
}

/// What a point gives back: its metrics and, if asked for, its recorded reading.
#[derive(Clone, Debug, PartialEq)]
pub struct PointOutput {
    pub metrics: PointMetrics,
    pub trace: Vec<f64>,
}

/// Outcome of a point.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[repr(u8)]
pub enum Status {
    /// not run (the batch was cancelled first)
    NotRun = 0,
    Ok = 1,
    /// diverged at the requested dt, finished at a smaller one (see `dt_used`)
    Retried = 2,
    /// diverged at every step tried (`diverged_at` holds the time)
    Diverged = 3,
    /// the point's parameters are invalid
    Invalid = 4,
}

/// Metrics of one point. NaN where not available.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PointMetrics {
    /// x1(t_end) [m]
    pub final_position: f64,
    /// x1(t_end) / cycles for trains [m]
    pub step_per_cycle: f64,
    /// max |v1| [m/s]
    pub peak_velocity: f64,
    /// max |Ff| [N]
    pub peak_friction: f64,
    /// share of time the main body slides, |v1| > SLIP_VELOCITY_FACTOR x stribeck_velocity [-]
    pub slip_fraction: f64,
    pub status: Status,
    /// time of the (last) divergence [s]
    pub diverged_at: f64,
    /// step used (RK4) or smallest accepted step (dopri5) [s]
    pub dt_used: f64,
    /// steps taken (accepted, for dopri5)
    pub steps: u64,
}

impl PointMetrics {
    pub fn not_run() -> Self {
        PointMetrics {
            final_position: f64::NAN,
            step_per_cycle: f64::NAN,
            peak_velocity: f64::NAN,
            peak_friction: f64::NAN,
            slip_fraction: f64::NAN,
            status: Status::NotRun,
            diverged_at: f64::NAN,
            dt_used: f64::NAN,
            steps: 0,
        }
    }
}

/// Running maxima and slip time of one point.
#[derive(Clone, Copy, Debug, Default)]
struct Accumulator {
    slip_velocity: f64,
    peak_v: f64,
    peak_f: f64,
    slip_time: f64,
}

impl Accumulator {
    fn new(model: &Model) -> Self {
        Accumulator {
            slip_velocity: SLIP_VELOCITY_FACTOR * model.params.stribeck_velocity,
            ..Default::default()
        }
    }

    /// Account for the state (v1, Ff) held over a time `span`.
    #[inline(always)]
    fn observe(&mut self, v1: f64, ff: f64, span: f64) {
        self.peak_v = self.peak_v.max(v1.abs());
        self.peak_f = self.peak_f.max(ff.abs());
        if v1.abs() > self.slip_velocity {
            self.slip_time += span;
        }
    }

    fn finish(
        self,
        model: &Model,
        y: &[f64],
        t_end: f64,
        cycles: usize,
        status: Status,
        dt_used: f64,
        steps: u64,
    ) -> PointMetrics {
        let v1 = y[model.layout.dof];
        let ff = model.friction_force(y);
        let mut acc = self;
        acc.observe(v1, ff, 0.0); // the final state counts for the peaks only
        PointMetrics {
            final_position: y[0],
            step_per_cycle: if cycles > 0 {
                y[0] / cycles as f64
            } else {
                f64::NAN
            },
            peak_velocity: acc.peak_v,
            peak_friction: acc.peak_f,
            slip_fraction: acc.slip_time / t_end,
            status,
            diverged_at: f64::NAN,
            dt_used,
            steps,
        }
    }
}

fn build_model(cfg: &BatchConfig, spec: &PointSpec) -> Result<Model, String> {
    Model::new(
        spec.params,
        spec.effects,
        cfg.structure,
        cfg.piezo_hysteresis,
        false,
    )
}

/// Input over step k of lane: (V at step start, slope), advancing the lane's segment cursor.
#[inline(always)]
fn step_input(wave: &PiecewiseLinear, seg: &mut usize, k: usize, dt: f64) -> (f64, f64) {
    let (bt, bv) = (wave.times(), wave.values());
    let t0 = k as f64 * dt;
    let t_mid = t0 + 0.5 * dt;
    while *seg + 1 < bt.len() && bt[*seg + 1] <= t_mid {
        *seg += 1;
    }
    if t_mid < bt[0] || *seg + 1 >= bt.len() {
        (bv[*seg], 0.0)
    } else {
        let s = (bv[*seg + 1] - bv[*seg]) / (bt[*seg + 1] - bt[*seg]);
        (bv[*seg] + s * (t0 - bt[*seg]), s)
    }
}

/// RK4 on up to L points at once (same state layout; each its own step count). An `Err` marks
/// a lane that diverged (with its time) — the caller retries it alone. Empty if cancelled.
fn rk4_lanes<S, const N: usize, const EXTRAS: bool, const L: usize>(
    models: &[Model],
    specs: &[&PointSpec],
    dt: f64,
    steps: &[usize],
    record_every: usize,
    zero: S,
    cancel: &AtomicBool,
) -> Vec<Result<PointOutput, f64>>
where
    S: AsRef<[f64]> + AsMut<[f64]> + Clone,
{
    let m = models.len();
    let mut active = [false; L];
    active[..m].fill(true);
    let mut ys: [S; L] = std::array::from_fn(|_| zero.clone());
    let mut rk: Rk4<S, L> = Rk4::new(zero.clone());
    let mut acc: [Accumulator; L] =
        std::array::from_fn(|i| Accumulator::new(&models[i.min(m - 1)]));
    let mut seg = [0usize; L];
    let mut failed = [f64::NAN; L];
    let mut traces: Vec<Vec<f64>> = (0..m)
        .map(|i| {
            if record_every == 0 {
                return Vec::new();
            }
            let mut v = Vec::with_capacity(steps[i] / record_every + 1);
            v.push(models[i].reading(0.0, ys[i].as_ref()));
            v
        })
        .collect();
    let bounds: Vec<f64> = models
        .iter()
        .map(|md| md.presliding_bound() * (1.0 + 1e-6) + 1e-12)
        .collect();
    let (ifh, iv) = (models[0].layout.fh, models[0].layout.dof);
    let mut rhs: [ModelRhs<N, EXTRAS, 1>; L] = std::array::from_fn(|i| ModelRhs {
        model: &models[i.min(m - 1)],
        v0: [0.0],
        slope: [0.0],
        dt,
        ff_gdot: [(0.0, 0.0)],
    });
    let max_steps = steps.iter().copied().max().unwrap_or(0);
    let mut until_record = record_every;
    for k in 0..max_steps {
        if k % CANCEL_CHECK_STEPS == 0 && cancel.load(Ordering::Relaxed) {
            return Vec::new();
        }
        let mut v_start = [0.0; L];
        for i in 0..m {
            active[i] &= k < steps[i];
            let (v0, s) = step_input(&specs[i].wave, &mut seg[i], k, dt);
            rhs[i].v0 = [v0];
            rhs[i].slope = [s];
            v_start[i] = ys[i].as_ref()[iv];
        }
        let mut f = |lane: usize, c: f64, y: &[f64], dy: &mut [f64]| rhs[lane].eval(0, c, y, dy);
        rk.step_lanes(&mut f, dt, &mut ys, &active);
        let t1 = (k + 1) as f64 * dt;
        until_record = until_record.wrapping_sub(1);
        for i in 0..m {
            if active[i] {
                // (Ff, dg/dt) from the first stage belong to the state at the step's start
                let (ff, _) = rhs[i].ff_gdot[0];
                acc[i].observe(v_start[i], ff, dt);
                let y = ys[i].as_ref();
                if !(y[ifh].abs() <= bounds[i]) || !y[iv].is_finite() || !y[0].is_finite() {
                    active[i] = false;
                    failed[i] = t1;
                } else if until_record == 0 {
                    traces[i].push(models[i].reading(t1, y));
                }
            }
        }
        if until_record == 0 {
            until_record = record_every;
        }
    }
    (0..m)
        .map(|i| {
            if failed[i].is_nan() && ys[i].as_ref().iter().all(|x| x.is_finite()) {
                let t_end = steps[i] as f64 * dt;
                let metrics = acc[i].finish(
                    &models[i],
                    ys[i].as_ref(),
                    t_end,
                    specs[i].cycles,
                    Status::Ok,
                    dt,
                    steps[i] as u64,
                );
                Ok(PointOutput {
                    metrics,
                    trace: std::mem::take(&mut traces[i]),
                })
            } else {
                Err(if failed[i].is_nan() {
                    steps[i] as f64 * dt
                } else {
                    failed[i]
                })
            }
        })
        .collect()
}

/// RK4 over a group of points with the same model layout, dispatched to a fixed-size state.
fn rk4_group(
    dt: f64,
    record_every: usize,
    models: &[Model],
    specs: &[&PointSpec],
    steps: &[usize],
    cancel: &AtomicBool,
) -> Vec<Result<PointOutput, f64>> {
    macro_rules! fixed {
        ($n:literal, $d:literal) => {
            rk4_lanes::<[f64; $d], $n, false, LANES>(
                models,
                specs,
                dt,
                steps,
                record_every,
                [0.0; $d],
                cancel,
            )
        };
    }
    let plain = models.iter().all(|m| m.is_plain());
    with_state_size!(plain, models[0].layout.dof, fixed, {
        let mut out = Vec::with_capacity(models.len());
        for (i, (m, s)) in models.iter().zip(specs).enumerate() {
            let r = rk4_lanes::<Vec<f64>, 0, true, 1>(
                std::slice::from_ref(m),
                &[*s],
                dt,
                &steps[i..=i],
                record_every,
                rest_state(m),
                cancel,
            );
            if r.is_empty() {
                return Vec::new(); // cancelled
            }
            out.extend(r);
        }
        out
    })
}

/// Adaptive Dormand-Prince runs of up to LANES points with one state layout, interleaved
/// stage by stage (see dopri5.rs), dispatched to a fixed-size state when plain. Empty if
/// cancelled.
fn dopri5_group(
    cfg: &BatchConfig,
    models: &[Model],
    specs: &[&PointSpec],
    rtol: f64,
    atol: f64,
    cancel: &AtomicBool,
) -> Vec<PointMetrics> {
    macro_rules! fixed {
        ($n:literal, $d:literal) => {
            dopri5_lanes::<[f64; $d], $n, false, LANES>(
                cfg, models, specs, rtol, atol, [0.0; $d], cancel,
            )
        };
    }
    let plain = models.iter().all(|m| m.is_plain());
    with_state_size!(plain, models[0].layout.dof, fixed, {
        let mut out = Vec::with_capacity(models.len());
        for (m, s) in models.iter().zip(specs) {
            let r = dopri5_lanes::<Vec<f64>, 0, true, 1>(
                cfg,
                std::slice::from_ref(m),
                &[*s],
                rtol,
                atol,
                rest_state(m),
                cancel,
            );
            if r.is_empty() {
                return Vec::new();
            }
            out.extend(r);
        }
        out
    })
}

fn dopri5_lanes<S, const N: usize, const EXTRAS: bool, const L: usize>(
    cfg: &BatchConfig,
    models: &[Model],
    specs: &[&PointSpec],
    rtol: f64,
    atol: f64,
    zero: S,
    cancel: &AtomicBool,
) -> Vec<PointMetrics>
where
    S: AsRef<[f64]> + AsMut<[f64]> + Clone,
{
    let m = models.len();
    // unused lanes repeat the last point with a zero duration: they finish at once
    let lane = |i: usize| i.min(m - 1);
    let t_end: [f64; L] = std::array::from_fn(|i| if i < m { specs[i].t_end(cfg) } else { 0.0 });
    let opts: Vec<Dopri5Options> = (0..L)
        .map(|i| {
            let (md, sp) = (&models[lane(i)], specs[lane(i)]);
            let v_max = sp.wave.values().iter().fold(0.0f64, |a, v| a.max(v.abs()));
            Dopri5Options {
                rtol,
                atol,
                scale: md.state_scales(v_max),
                h_init: cfg.dt,
                h_min: 1e-14,
                h_max: (t_end[i] / 10.0).max(cfg.dt),
            }
        })
        .collect();
    let mut ys: [S; L] = std::array::from_fn(|_| zero.clone());
    let mut acc: [Accumulator; L] = std::array::from_fn(|i| Accumulator::new(&models[lane(i)]));
    let mut t_prev = [0.0; L];
    let mut h_min_used = [f64::INFINITY; L];
    let mut v_prev = [0.0; L];
    let mut ff_prev = [0.0; L];
    let mut accepted = 0usize;
    let mut cancelled = false;
    let results = dopri5::integrate_lanes(
        |i: usize, seg: usize, t: f64, s: &[f64], ds: &mut [f64]| {
            // V(t) on the segment that starts at breakpoint `seg` (constant after the last)
            let (bt, bv) = (specs[lane(i)].wave.times(), specs[lane(i)].wave.values());
            let (v, slope) = if seg + 1 >= bt.len() || t < bt[0] {
                (bv[seg.min(bt.len() - 1)], 0.0)
            } else {
                let sl = (bv[seg + 1] - bv[seg]) / (bt[seg + 1] - bt[seg]);
                (bv[seg] + sl * (t - bt[seg]), sl)
            };
            models[lane(i)].rhs_impl::<N, EXTRAS>(v, slope, s, ds);
        },
        [0.0; L],
        t_end,
        std::array::from_fn(|i| specs[lane(i)].wave.times()),
        &mut ys,
        std::array::from_fn(|i| &opts[i]),
        |i, t, s| {
            // the state at the start of each accepted step is held over it
            acc[i].observe(v_prev[i], ff_prev[i], t - t_prev[i]);
            h_min_used[i] = h_min_used[i].min(t - t_prev[i]);
            t_prev[i] = t;
            v_prev[i] = s[models[lane(i)].layout.dof];
            ff_prev[i] = models[lane(i)].friction_force(s);
            accepted += 1;
            if accepted % 4096 == 0 && cancel.load(Ordering::Relaxed) {
                cancelled = true;
            }
            !cancelled
        },
    );
    if cancelled {
        return Vec::new();
    }
    (0..m)
        .map(|i| {
            let y = ys[i].as_ref();
            match &results[i] {
                Ok(stats) if y.iter().all(|x| x.is_finite()) => acc[i].finish(
                    &models[i],
                    y,
                    t_end[i],
                    specs[i].cycles,
                    Status::Ok,
                    h_min_used[i],
                    stats.accepted,
                ),
                Ok(_) => diverged_metrics(t_end[i], cfg.dt),
                Err((t, _)) => diverged_metrics(*t, cfg.dt),
            }
        })
        .collect()
}

fn diverged_metrics(t: f64, dt: f64) -> PointMetrics {
    PointMetrics {
        status: Status::Diverged,
        diverged_at: t,
        dt_used: dt,
        ..PointMetrics::not_run()
    }
}

/// RK4 retry of one diverged point at dt/2, dt/4, ... (recording at the same times).
fn rk4_retry(
    cfg: &BatchConfig,
    model: &Model,
    spec: &PointSpec,
    first_failure: f64,
    cancel: &AtomicBool,
) -> Option<PointOutput> {
    let mut failed_at = first_failure;
    let (mut dt, mut record_every) = (cfg.dt, cfg.record_every);
    for _ in 0..cfg.retries {
        dt /= 2.0;
        record_every *= 2;
        let steps = match plan_steps(model, &spec.wave, spec.t_end(cfg), dt) {
            Ok(s) => s,
            Err(_) => break,
        };
        match rk4_group(
            dt,
            record_every,
            std::slice::from_ref(model),
            &[spec],
            &[steps],
            cancel,
        )
        .pop()
        {
            None => return None, // cancelled
            Some(Ok(o)) => {
                return Some(PointOutput {
                    metrics: PointMetrics {
                        status: Status::Retried,
                        ..o.metrics
                    },
                    trace: o.trace,
                })
            }
            Some(Err(t)) => failed_at = t,
        }
    }
    Some(PointOutput {
        metrics: PointMetrics {
            dt_used: dt,
            ..diverged_metrics(failed_at, dt)
        },
        trace: Vec::new(),
    })
}

/// End of the lane group starting at `start`: up to LANES points sharing one state layout.
fn lane_group_end(valid: &[(usize, Model, usize)], start: usize) -> usize {
    let dim = valid[start].1.layout.dim;
    let mut end = start + 1;
    while end < valid.len() && end - start < LANES && valid[end].1.layout.dim == dim {
        end += 1;
    }
    end
}

/// Run one chunk of points (any size); `None` entries were cancelled before finishing.
fn run_chunk(
    cfg: &BatchConfig,
    specs: &[PointSpec],
    cancel: &AtomicBool,
    done: &AtomicUsize,
) -> Vec<Option<PointOutput>> {
    let mut out: Vec<Option<PointOutput>> = vec![None; specs.len()];
    // invalid points are answered at once; valid ones are grouped by layout for the lanes
    let mut valid: Vec<(usize, Model, usize)> = Vec::with_capacity(specs.len());
    for (i, s) in specs.iter().enumerate() {
        let checked = build_model(cfg, s).and_then(|m| {
            let steps = match cfg.method {
                Method::Rk4 => {
                    plan_steps(&m, &s.wave, s.t_end(cfg), cfg.dt).map_err(|e| e.to_string())?
                }
                Method::Dopri5 { .. } => 0,
            };
            Ok((m, steps))
        });
        match checked {
            Ok((m, steps)) => valid.push((i, m, steps)),
            Err(_) => {
                let metrics = PointMetrics {
                    status: Status::Invalid,
                    ..PointMetrics::not_run()
                };
                out[i] = Some(PointOutput {
                    metrics,
                    trace: Vec::new(),
                });
                done.fetch_add(1, Ordering::Relaxed);
            }
        }
    }
    // lane groups: up to LANES points sharing one state layout, run together
    let mut start = 0;
    while start < valid.len() {
        if cancel.load(Ordering::Relaxed) {
            break;
        }
        let end = lane_group_end(&valid, start);
        let group = &valid[start..end];
        let models: Vec<Model> = group.iter().map(|(_, m, _)| m.clone()).collect();
        let gspecs: Vec<&PointSpec> = group.iter().map(|(i, _, _)| &specs[*i]).collect();
        let results: Vec<Option<PointOutput>> = match cfg.method {
            Method::Rk4 => {
                let steps: Vec<usize> = group.iter().map(|(_, _, s)| *s).collect();
                let r = rk4_group(cfg.dt, cfg.record_every, &models, &gspecs, &steps, cancel);
                if r.is_empty() {
                    break; // cancelled
                }
                group
                    .iter()
                    .zip(r)
                    .map(|((i, m, _), r)| match r {
                        Ok(x) => Some(x),
                        Err(t) => rk4_retry(cfg, m, &specs[*i], t, cancel),
                    })
                    .collect()
            }
            Method::Dopri5 { rtol, atol } => {
                let r = dopri5_group(cfg, &models, &gspecs, rtol, atol, cancel);
                if r.is_empty() {
                    break; // cancelled
                }
                r.into_iter().map(|metrics| Some(PointOutput { metrics, trace: Vec::new() })).collect()
            }
        };
        for ((i, _, _), res) in group.iter().zip(results) {
            if res.is_some() {
                done.fetch_add(1, Ordering::Relaxed);
            }
            out[*i] = res;
        }
        start = end;
    }
    out
}

/// Points per rayon task: one lane group. A task is milliseconds of work or more, so
/// scheduling costs nothing, and small tasks balance the threads when a batch has few points
/// (a fit's Jacobian) or points of very different cost.
pub const CHUNK: usize = LANES;

/// Run every point on the current rayon pool. Unfinished points (after `cancel`) come back as
/// `Status::NotRun` with NaN metrics; `done` counts finished points as they finish.
pub fn run_batch(
    cfg: &BatchConfig,
    specs: &[PointSpec],
    cancel: &AtomicBool,
    done: &AtomicUsize,
) -> Result<Vec<PointOutput>, SimError> {
    if !(cfg.dt.is_finite() && cfg.dt > 0.0) {
        return Err(SimError::Input(format!(
            "parameter 'dt' must be positive and finite, got {}",
            cfg.dt
        )));
    }
    if let Method::Dopri5 { rtol, atol } = cfg.method {
        if !(rtol > 0.0 && atol > 0.0 && rtol.is_finite() && atol.is_finite()) {
            return Err(SimError::Input(format!(
                "'rtol' and 'atol' must be positive, got {rtol}, {atol}"
            )));
        }
        if cfg.record_every > 0 {
            return Err(SimError::Input(
                "recording readings needs method 'rk4'".into(),
            ));
        }
    }
    Ok(specs
        .par_chunks(CHUNK)
        .flat_map_iter(|chunk| run_chunk(cfg, chunk, cancel, done))
        .map(|m| {
            m.unwrap_or_else(|| PointOutput {
                metrics: PointMetrics::not_run(),
                trace: Vec::new(),
            })
        })
        .collect())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::simulate::simulate;

    fn cfg(method: Method, structure: Structure) -> BatchConfig {
        BatchConfig {
            structure,
            piezo_hysteresis: true,
            t_end: 2e-3,
            dt: 2e-8,
            method,
            retries: 2,
            record_every: 0,
        }
    }

    fn specs(n: usize) -> Vec<PointSpec> {
        (0..n)
            .map(|i| {
                let mut p = Params::paper();
                p.m2 = 0.15 + 0.05 * i as f64;
                p.normal_force = p.default_normal_force();
                PointSpec {
                    params: p,
                    effects: Effects::default(),
                    wave: PiecewiseLinear::sawtooth(
                        40.0 + 10.0 * i as f64,
                        1000.0,
                        2,
                        0.2e-3,
                        true,
                        0.0,
                    )
                    .unwrap(),
                    cycles: 2,
                    t_end: None,
                }
            })
            .collect()
    }

    #[test]
    fn rk4_batch_equals_simulate_bitwise() {
        for structure in [Structure::Lps, Structure::Dps(4)] {
            let c = cfg(Method::Rk4, structure);
            let sp = specs(7);
            let (cancel, done) = (AtomicBool::new(false), AtomicUsize::new(0));
            let r: Vec<PointMetrics> = run_batch(&c, &sp, &cancel, &done)
                .unwrap()
                .into_iter()
                .map(|o| o.metrics)
                .collect();
            assert_eq!(done.load(Ordering::Relaxed), 7);
            for (s, m) in sp.iter().zip(&r) {
                let model = Model::new(s.params, s.effects, structure, true, false).unwrap();
                let t = simulate(&model, &s.wave, c.t_end, c.dt, 1).unwrap();
                assert_eq!(m.status, Status::Ok);
                assert_eq!(m.final_position, t.final_state[0]);
                let pv = t
                    .velocities
                    .chunks(model.layout.dof)
                    .map(|v| v[0].abs())
                    .fold(0.0, f64::max);
                let pf = t.friction.iter().fold(0.0f64, |a, f| a.max(f.abs()));
                assert_eq!(m.peak_velocity, pv);
                assert_eq!(m.peak_friction, pf);
                assert!(m.slip_fraction > 0.0 && m.slip_fraction < 1.0);
            }
        }
    }

    #[test]
    fn results_do_not_depend_on_thread_count() {
        let c = cfg(Method::Rk4, Structure::Lps);
        let sp = specs(9);
        let run = |threads: usize| {
            let pool = rayon::ThreadPoolBuilder::new()
                .num_threads(threads)
                .build()
                .unwrap();
            pool.install(|| {
                run_batch(&c, &sp, &AtomicBool::new(false), &AtomicUsize::new(0)).unwrap()
            })
            .into_iter()
            .map(|o| o.metrics)
            .collect::<Vec<_>>()
        };
        let bits = |r: Vec<PointMetrics>| -> Vec<[u64; 7]> {
            r.iter()
                .map(|m| {
                    [
                        m.final_position,
                        m.step_per_cycle,
                        m.peak_velocity,
                        m.peak_friction,
                        m.slip_fraction,
                        m.diverged_at,
                        m.dt_used,
                    ]
                    .map(f64::to_bits)
                })
                .collect()
        };
        assert_eq!(bits(run(1)), bits(run(2)));
    }

    #[test]
    fn dopri5_agrees_with_rk4_to_a_nanometre() {
        let sp = specs(3);
        let (cancel, done) = (AtomicBool::new(false), AtomicUsize::new(0));
        let a = run_batch(&cfg(Method::Rk4, Structure::Lps), &sp, &cancel, &done).unwrap();
        let b = run_batch(
            &cfg(
                Method::Dopri5 {
                    rtol: 1e-7,
                    atol: 1e-7,
                },
                Structure::Lps,
            ),
            &sp,
            &cancel,
            &done,
        )
        .unwrap();
        for (x, y) in a.iter().map(|o| o.metrics).zip(b.iter().map(|o| o.metrics)) {
            assert_eq!(y.status, Status::Ok);
            assert!(
                (x.final_position - y.final_position).abs() < 1e-9,
                "{} {}",
                x.final_position,
                y.final_position
            );
            assert!(y.steps < 100_000 / 2, "adaptive took {} steps", y.steps);
        }
    }

    #[test]
    fn diverging_point_is_retried_and_does_not_poison_others() {
        let mut c = cfg(Method::Rk4, Structure::Lps);
        c.dt = 4e-7;
        c.t_end = 2e-3;
        let sp = specs(3);
        let metrics = |c: &BatchConfig| -> Vec<PointMetrics> {
            run_batch(c, &sp, &AtomicBool::new(false), &AtomicUsize::new(0))
                .unwrap()
                .into_iter()
                .map(|o| o.metrics)
                .collect()
        };
        let r = metrics(&c);
        assert!(r.iter().any(|m| m.status == Status::Retried), "{r:?}");
        assert!(r.iter().all(|m| m.final_position.is_finite()));
        c.retries = 0;
        let r = metrics(&c);
        assert!(r.iter().any(|m| m.status == Status::Diverged
            && m.diverged_at > 0.0
            && m.final_position.is_nan()));
    }

    #[test]
    fn cancelled_batch_returns_not_run_points() {
        let c = cfg(Method::Rk4, Structure::Lps);
        let cancel = AtomicBool::new(true);
        let r = run_batch(&c, &specs(5), &cancel, &AtomicUsize::new(0)).unwrap();
        assert!(r
            .iter()
            .all(|o| o.metrics.status == Status::NotRun && o.metrics.final_position.is_nan()));
    }

    #[test]
    fn recorded_traces_equal_simulate_readings_for_mixed_durations() {
        let mut c = cfg(Method::Rk4, Structure::Dps(4));
        c.record_every = 50;
        let mut sp = specs(5);
        sp[1].t_end = Some(1e-3);
        sp[3].t_end = Some(1.5e-3);
        sp[4].effects.tau_sensor = 2e-5; // an extra state: takes the general path
        let r = run_batch(&c, &sp, &AtomicBool::new(false), &AtomicUsize::new(0)).unwrap();
        for (s, o) in sp.iter().zip(&r) {
            let model = Model::new(s.params, s.effects, Structure::Dps(4), true, false).unwrap();
            let t = simulate(&model, &s.wave, s.t_end.unwrap_or(c.t_end), c.dt, 50).unwrap();
            assert_eq!(o.trace, t.reading);
            assert_eq!(o.metrics.final_position, t.final_state[0]);
        }
    }
}
