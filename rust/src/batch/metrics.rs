//! Sweep metrics of a point, accumulated inside the step loop by an observer of the driver (no
//! trajectory is stored), and the point's recorded sensor readings when a fit asks for them.

use crate::integrate::task::Observer;
use crate::model::Model;

use super::steady::{CycleStats, Steady, Train};
use super::Status;

/// The main body counts as sliding when |v1| exceeds this share of the Stribeck velocity:
/// presliding (elastic asperity) motion is orders of magnitude slower.
pub const SLIP_VELOCITY_FACTOR: f64 = 0.1;

/// The speed above which the main body counts as sliding for `slip_fraction` [m/s] (the GPU
/// kernel reads the same, `gpu/generate.rs`).
pub fn slip_velocity(m: &Model) -> f64 {
    SLIP_VELOCITY_FACTOR * m.params.stribeck_velocity
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
    /// step used (RK4) or smallest accepted step (adaptive) [s]
    pub dt_used: f64,
    /// steps taken (accepted, for adaptive methods)
    pub steps: u64,
    /// steady-state metrics of a sawtooth train (NaN otherwise)
    pub steady: Steady,
}

/// A metric column of a batch's result: its name, unit, long name and value at a point.
pub type MetricColumn = (&'static str, &'static str, &'static str, fn(&PointMetrics) -> f64);

/// The metric columns a batch returns, declared once: the binding hands them to Python by these
/// names, and `sweep.py` takes its metrics' units and long names from here
/// (`engine.metric_columns()`). The steady-state ones are NaN except for sawtooth trains.
pub const METRIC_COLUMNS: [MetricColumn; 11] = [
    ("final_position", "m", "main body displacement x1 at t_end", |m| {
        m.final_position
    }),
    (
        "step_per_cycle",
        "m",
        "mean main body step per drive cycle, x1(t_end)/cycles",
        |m| m.step_per_cycle,
    ),
    ("peak_velocity", "m/s", "largest |v1|", |m| m.peak_velocity),
    ("peak_friction", "N", "largest |Ff|", |m| m.peak_friction),
    (
        "slip_fraction",
        "1",
        "share of time the main body slides (|v1| > 0.1 stribeck_velocity)",
        |m| m.slip_fraction,
    ),
    (
        "mean_velocity",
        "m/s",
        "steady-state mean velocity of the main body, mean step x frequency",
        |m| m.steady.mean_velocity,
    ),
    (
        "step_mean",
        "m",
        "mean main body step per drive cycle (steady state)",
        |m| m.steady.step_mean,
    ),
    (
        "step_std",
        "m",
        "standard deviation of the step over the steady-state cycles",
        |m| m.steady.step_std,
    ),
    (
        "backslip",
        "m",
        "mean back-slip per cycle: travel against the net direction",
        |m| m.steady.backslip,
    ),
    (
        "backslip_ratio",
        "1",
        "back-slip over the travel along the net direction",
        |m| m.steady.backslip_ratio,
    ),
    (
        "direction",
        "1",
        "net motion: +1 forward, -1 backward, 0 stalled (|step| < 1e-3 d33 V)",
        |m| m.steady.direction,
    ),
];

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
            steady: Steady::none(),
        }
    }

    pub fn with_status(status: Status) -> Self {
        PointMetrics {
            status,
            ..PointMetrics::not_run()
        }
    }

    pub fn diverged(t: f64, dt_used: f64) -> Self {
        PointMetrics {
            diverged_at: t,
            dt_used,
            ..PointMetrics::with_status(Status::Diverged)
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
    /// Account for the state (v1, Ff) held over a time `span`.
    #[inline(always)]
    fn observe(&mut self, v1: f64, ff: f64, span: f64) {
        self.peak_v = self.peak_v.max(v1.abs());
        self.peak_f = self.peak_f.max(ff.abs());
        if v1.abs() > self.slip_velocity {
            self.slip_time += span;
        }
    }
}

/// The batch's observer: per task, the metrics accumulator and the recorded readings.
pub struct MetricsObserver<'a> {
    models: Vec<&'a Model>,
    acc: Vec<Accumulator>,
    /// v1 [m/s] and Ff [N] of the state each step starts from
    v_prev: Vec<f64>,
    ff_prev: Vec<f64>,
    record_every: usize,
    until_record: Vec<usize>,
    pub traces: Vec<Vec<f64>>,
    cycles: Vec<CycleStats>,
}

impl<'a> MetricsObserver<'a> {
    /// For `models` (one per task), recording the reading every `record_every` steps (0: never);
    /// `trains[i]` (with its free stroke d33 V [m]) is task i's sawtooth train, if any, whose
    /// first `skip_cycles` cycles the steady-state metrics skip.
    pub fn new(
        models: Vec<&'a Model>,
        record_every: usize,
        steps_hint: &[usize],
        trains: &[(Option<Train>, f64)],
        skip_cycles: usize,
    ) -> Self {
        let n = models.len();
        MetricsObserver {
            cycles: (0..n)
                .map(|i| {
                    let (train, stroke) = trains.get(i).copied().unwrap_or((None, f64::NAN));
                    CycleStats::new(train, skip_cycles, stroke)
                })
                .collect(),
            acc: models
                .iter()
                .map(|m| Accumulator {
                    slip_velocity: slip_velocity(m),
                    ..Default::default()
                })
                .collect(),
            v_prev: vec![0.0; n],
            ff_prev: vec![0.0; n],
            record_every,
            until_record: vec![record_every; n],
            traces: (0..n)
                .map(|i| match record_every {
                    0 => Vec::new(),
                    r => Vec::with_capacity(steps_hint.get(i).copied().unwrap_or(0) / r + 1),
                })
                .collect(),
            models,
        }
    }

    /// The metrics of task `i` that finished in state `y` after `duration` [s].
    pub fn finish(&self, i: usize, y: &[f64], duration: f64, dt_used: f64, steps: u64) -> PointMetrics {
        let cycles = self.cycles[i].train().map_or(0, |t| t.cycles);
        let model = self.models[i];
        let mut acc = self.acc[i];
        acc.observe(y[model.layout.dof], model.friction_force(y), 0.0); // peaks only
        PointMetrics {
            final_position: y[0],
            step_per_cycle: if cycles > 0 { y[0] / cycles as f64 } else { f64::NAN },
            peak_velocity: acc.peak_v,
            peak_friction: acc.peak_f,
            slip_fraction: acc.slip_time / duration,
            status: Status::Ok,
            diverged_at: f64::NAN,
            dt_used,
            steps,
            steady: self.cycles[i].finish(),
        }
    }
}

impl Observer for MetricsObserver<'_> {
    fn start(&mut self, i: usize, t: f64, y: &[f64]) {
        let model = self.models[i];
        self.v_prev[i] = y[model.layout.dof];
        self.ff_prev[i] = model.friction_force(y);
        self.cycles[i].start(t, y[0]);
        if self.record_every > 0 {
            self.traces[i].push(model.reading(t, y));
        }
    }

    #[inline(always)]
    fn step(&mut self, i: usize, t: f64, span: f64, y: &[f64], _v: f64, start: Option<(f64, f64)>, _last: bool) {
        let model = self.models[i];
        // the state at the start of each step is held over it
        let ff = match start {
            Some((ff, _)) => ff,
            None => self.ff_prev[i],
        };
        self.acc[i].observe(self.v_prev[i], ff, span);
        self.v_prev[i] = y[model.layout.dof];
        if start.is_none() {
            self.ff_prev[i] = model.friction_force(y);
        }
        self.cycles[i].observe(t, y[0]);
        if self.record_every > 0 {
            self.until_record[i] -= 1;
            if self.until_record[i] == 0 {
                self.traces[i].push(model.reading(t, y));
                self.until_record[i] = self.record_every;
            }
        }
    }
}
