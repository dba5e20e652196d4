//! The batch engine behind sweeps and fits: many independent points (parameters, effects,
//! input, span, initial state), each reduced to a few metrics inside the loop (`metrics.rs`) —
//! no trajectory is stored, so memory is O(points x metrics). Points run in parallel with rayon
//! (`run.rs`), grouped into lanes of the one driver (`drive/`); a background thread with
//! progress and cancellation runs a whole batch (`runner.rs`). Every point's arithmetic is
//! exactly that of `simulate` for the same settings, so results do not depend on thread count,
//! chunking or lane grouping.

mod metrics;
mod points;
mod run;
mod runner;
mod steady;

pub use metrics::{slip_velocity, MetricColumn, PointMetrics, METRIC_COLUMNS, SLIP_VELOCITY_FACTOR};
pub use points::{row_point, PointTables, WaveFamily};
pub use run::{run_batch, CHUNK, LANES};
pub use runner::BatchRunner;
pub use steady::{Steady, Train, STALL_STEP_FRACTION};

use crate::error::InputError;
use crate::integrate::method::Method;
use crate::physics::effects::Effects;
use crate::physics::mechanics::Structure;
use crate::physics::params::Params;
use crate::physics::waveform::PiecewiseLinear;

/// What is common to every point of a batch.
#[derive(Clone, Debug)]
pub struct BatchConfig {
    pub structure: Structure,
    pub piezo_hysteresis: bool,
    /// end of every point's run unless the point sets its own [s]
    pub t_end: f64,
    pub method: Method,
    /// RK4: on divergence, retry with dt/2, dt/4, ... this many times before flagging the point
    pub retries: u32,
    /// RK4: record the sensor reading at the start and every `record_every` steps (0: none). The
    /// only per-time output of a batch; fits compare it with recordings.
    pub record_every: usize,
    /// return each point's final state (to continue it, or to chain segments of a record)
    pub final_states: bool,
    /// start-up cycles of a sawtooth train left out of the steady-state metrics
    pub skip_cycles: usize,
    /// names whose derivatives of the recorded readings each point returns (Table 1 and
    /// effect parameters, initial-state components; see `sensitivity/`); empty for none
    pub sensitivities: Vec<String>,
    /// only the derivative passes: the caller already has every point's readings from a plain
    /// run of the same points that finished at the configured step (a fit's Jacobian is taken
    /// where its last evaluation ran), so that run is not repeated; traces come back empty and
    /// the metrics carry only `status` Ok and `dt_used`. Needs `sensitivities` and RK4.
    pub derivatives_only: bool,
}

impl BatchConfig {
    /// Refuse a method with bad settings, or recorded readings with an adaptive method (they are
    /// taken every so many fixed steps).
    pub fn validate(&self) -> Result<(), InputError> {
        self.method.validate()?;
        if !self.method.is_fixed() && self.record_every > 0 {
            return Err("recording readings needs method 'rk4'".into());
        }
        if self.derivatives_only && self.sensitivities.is_empty() {
            return Err("derivatives_only runs the derivative passes alone: name the sensitivities".into());
        }
        if !self.sensitivities.is_empty() && self.record_every == 0 {
            return Err(
                "sensitivities are derivatives of the recorded readings: set record_every (and method 'rk4')".into(),
            );
        }
        Ok(())
    }
}

/// One point: its parameters, effects, input and its drive cycles (if a sawtooth train).
#[derive(Clone, Debug)]
pub struct PointSpec {
    pub params: Params,
    pub effects: Effects,
    pub wave: PiecewiseLinear,
    pub train: Option<Train>,
    /// this point's end time [s] if it differs from the batch's `t_end`
    pub t_end: Option<f64>,
    /// start time [s] (0: from the beginning of the input)
    pub t_start: f64,
    /// initial state (see `Layout::components`); `None`: at rest
    pub y0: Option<Vec<f64>>,
    /// the normal force was derived from the masses (its derivative follows theirs)
    pub normal_force_derived: bool,
}

impl PointSpec {
    /// A point run from rest over [0, the batch's t_end].
    pub fn new(params: Params, effects: Effects, wave: PiecewiseLinear, train: Option<Train>) -> Self {
        PointSpec {
            params,
            effects,
            wave,
            train,
            t_end: None,
            t_start: 0.0,
            y0: None,
            normal_force_derived: false,
        }
    }

    pub fn t_end(&self, cfg: &BatchConfig) -> f64 {
        self.t_end.unwrap_or(cfg.t_end)
    }
}

/// What a point gives back: its metrics, its recorded reading and its final state if asked.
#[derive(Clone, Debug, PartialEq)]
pub struct PointOutput {
    pub metrics: PointMetrics,
    pub trace: Vec<f64>,
    pub final_state: Vec<f64>,
    /// d trace / d name for the batch's sensitivity names, row-major [name][sample] (empty
    /// unless asked)
    pub sensitivities: Vec<f64>,
    /// why the status is not `Ok` (empty when it is)
    pub reason: String,
}

impl PointOutput {
    pub fn with_status(status: Status) -> Self {
        PointOutput {
            metrics: PointMetrics::with_status(status),
            trace: Vec::new(),
            final_state: Vec::new(),
            sensitivities: Vec::new(),
            reason: match status {
                Status::NotRun => "not run: the batch was cancelled first".into(),
                _ => String::new(),
            },
        }
    }

    /// A point that could not be built or run, and why.
    pub fn invalid(reason: String) -> Self {
        PointOutput {
            reason,
            ..PointOutput::with_status(Status::Invalid)
        }
    }
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
    /// the point's parameters, input or initial state are invalid
    Invalid = 4,
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::model::Model;
    use crate::simulate::simulate_from_rest as simulate;
    use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};

    const RK4: Method = Method::Rk4 { dt: 2e-8 };

    fn cfg(method: Method, structure: Structure) -> BatchConfig {
        BatchConfig {
            structure,
            piezo_hysteresis: true,
            t_end: 2e-3,
            method,
            retries: 2,
            record_every: 0,
            final_states: false,
            skip_cycles: 0,
            sensitivities: Vec::new(),
            derivatives_only: false,
        }
    }

    fn specs(n: usize) -> Vec<PointSpec> {
        (0..n)
            .map(|i| {
                let mut p = Params::paper();
                p.m2 = 0.15 + 0.05 * i as f64;
                p.normal_force = p.default_normal_force();
                PointSpec::new(
                    p,
                    Effects::default(),
                    PiecewiseLinear::sawtooth(40.0 + 10.0 * i as f64, 1000.0, 2, 0.2e-3, true, 0.0).unwrap(),
                    Some(Train::new(1000.0, 2, 0.0)),
                )
            })
            .collect()
    }

    #[test]
    fn rk4_batch_equals_simulate_bitwise() {
        for structure in [Structure::Lps, Structure::Dps(4)] {
            let mut c = cfg(RK4, structure);
            c.t_end = 1e-3; // a cycle, its slip and its stick: bitwise equality needs no more
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
                let t = simulate(&model, &s.wave, c.t_end, 2e-8, 1).unwrap();
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
        let c = cfg(RK4, Structure::Lps);
        let sp = specs(9);
        let run = |threads: usize| {
            let pool = rayon::ThreadPoolBuilder::new().num_threads(threads).build().unwrap();
            pool.install(|| run_batch(&c, &sp, &AtomicBool::new(false), &AtomicUsize::new(0)).unwrap())
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
        let a = run_batch(&cfg(RK4, Structure::Lps), &sp, &cancel, &done).unwrap();
        let b = run_batch(
            &cfg(
                Method::Dopri5 {
                    rtol: 1e-7,
                    atol: 1e-7,
                    first_step: 2e-8,
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
        let mut c = cfg(RK4, Structure::Lps);
        c.method = Method::Rk4 { dt: 4e-7 };
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
        assert!(r
            .iter()
            .any(|m| m.status == Status::Diverged && m.diverged_at > 0.0 && m.final_position.is_nan()));
    }

    #[test]
    fn points_retried_together_come_out_as_each_retried_alone() {
        // several points of one lane group diverge at the step and are retried together on
        // lanes: each output (trace, final state, derivatives, metrics, reason) is bitwise the
        // one the point gives in a batch of its own
        let mut c = cfg(RK4, Structure::Lps);
        c.method = Method::Rk4 { dt: 4e-7 };
        c.record_every = 5;
        c.final_states = true;
        c.sensitivities = vec!["mu_k".into()];
        let sp = specs(8);
        let run = |points: &[PointSpec]| run_batch(&c, points, &AtomicBool::new(false), &AtomicUsize::new(0)).unwrap();
        let together = run(&sp);
        let retried = together.iter().filter(|o| o.metrics.status == Status::Retried).count();
        assert!(retried >= 2, "{retried} points retried: the test needs several");
        for (i, o) in together.iter().enumerate() {
            let alone = run(&sp[i..i + 1]).pop().unwrap();
            let bits = |x: &[f64]| x.iter().map(|v| v.to_bits()).collect::<Vec<_>>();
            assert_eq!(bits(&o.trace), bits(&alone.trace), "point {i}");
            assert_eq!(bits(&o.final_state), bits(&alone.final_state), "point {i}");
            assert_eq!(bits(&o.sensitivities), bits(&alone.sensitivities), "point {i}");
            assert_eq!(format!("{:?}", o.metrics), format!("{:?}", alone.metrics), "point {i}");
            assert_eq!(o.reason, alone.reason, "point {i}");
        }
    }

    #[test]
    fn cancelled_batch_returns_not_run_points() {
        let c = cfg(RK4, Structure::Lps);
        let cancel = AtomicBool::new(true);
        let r = run_batch(&c, &specs(5), &cancel, &AtomicUsize::new(0)).unwrap();
        assert!(r
            .iter()
            .all(|o| o.metrics.status == Status::NotRun && o.metrics.final_position.is_nan()));
    }

    #[test]
    fn a_small_batch_balanced_over_threads_returns_every_point_in_its_place() {
        // four points of different spans (a fit's experiments) run lane by lane in tasks
        // balanced by span on two threads: the same bits, in the same order, as on one
        let mut c = cfg(RK4, Structure::Lps);
        c.record_every = 50;
        let mut sp = specs(4);
        for (s, t) in sp.iter_mut().zip([0.9e-3, 0.4e-3, 1.1e-3, 2e-3]) {
            s.t_end = Some(t);
        }
        let run = |threads: usize| {
            let pool = rayon::ThreadPoolBuilder::new().num_threads(threads).build().unwrap();
            pool.install(|| run_batch(&c, &sp, &AtomicBool::new(false), &AtomicUsize::new(0)).unwrap())
        };
        let (one, two) = (run(1), run(2));
        for (k, (a, b)) in one.iter().zip(&two).enumerate() {
            assert_eq!(a.trace, b.trace, "point {k}");
            assert_eq!(a.metrics.final_position.to_bits(), b.metrics.final_position.to_bits());
            assert_eq!(a.trace.len(), (sp[k].t_end.unwrap() / 2e-8 / 50.0).round() as usize + 1);
        }
    }

    #[test]
    fn recorded_traces_equal_simulate_readings_for_mixed_durations() {
        let mut c = cfg(RK4, Structure::Dps(4));
        c.record_every = 50;
        let mut sp = specs(5);
        sp[1].t_end = Some(1e-3);
        sp[3].t_end = Some(1.5e-3);
        sp[4].effects.tau_sensor = 2e-5; // an extra state: takes the general path
        let r = run_batch(&c, &sp, &AtomicBool::new(false), &AtomicUsize::new(0)).unwrap();
        for (s, o) in sp.iter().zip(&r) {
            let model = Model::new(s.params, s.effects, Structure::Dps(4), true, false).unwrap();
            let t = simulate(&model, &s.wave, s.t_end.unwrap_or(c.t_end), 2e-8, 50).unwrap();
            assert_eq!(o.trace, t.reading);
            assert_eq!(o.metrics.final_position, t.final_state[0]);
        }
    }

    #[test]
    fn batch_sensitivities_equal_those_of_a_single_run() {
        use crate::sensitivity::{derivatives, parse_seeds, Schedule};
        // dt within the friction state's stability limit at the sliding speeds of these points
        let rk4 = Method::Rk4 { dt: 5e-9 };
        let mut c = cfg(rk4, Structure::Lps);
        c.record_every = 200;
        c.t_end = 0.5e-3; // the fast edge's slip and the stick after it: bitwise equality needs no more
        let names = ["mu_k", "m2", "k_ground", "q0"];
        c.sensitivities = names.iter().map(|s| s.to_string()).collect();
        let mut sp = specs(3);
        sp[1].effects.k_ground = 500.0;
        sp[2].normal_force_derived = true;
        let r = run_batch(&c, &sp, &AtomicBool::new(false), &AtomicUsize::new(0)).unwrap();
        for (s, o) in sp.iter().zip(&r) {
            let model = Model::new(s.params, s.effects, Structure::Lps, true, false).unwrap();
            let seeds = parse_seeds(&model, &c.sensitivities, s.normal_force_derived).unwrap();
            let schedule = Schedule {
                every: 200,
                also_last: false,
            };
            let d = derivatives(
                &model,
                &s.wave,
                0.0,
                c.t_end,
                &model.rest_state(),
                &rk4,
                &Default::default(),
                schedule,
                &seeds,
                s.normal_force_derived,
                &AtomicBool::new(false),
            )
            .unwrap()
            .unwrap();
            let nt = o.trace.len();
            assert_eq!(o.sensitivities.len(), names.len() * nt);
            for j in 0..names.len() {
                for t in 0..nt {
                    assert_eq!(
                        o.sensitivities[j * nt + t],
                        d.readings[t * names.len() + j],
                        "{} at {t}",
                        names[j]
                    );
                }
            }
        }
        // the derived normal force makes d/dm2 differ
        assert_ne!(
            r[0].sensitivities[nt_of(&r[0]) * 2 - 1],
            r[2].sensitivities[nt_of(&r[2]) * 2 - 1]
        );
        assert!(r.iter().all(|o| o.sensitivities.iter().all(|x| x.is_finite())));
        // at RK4's stability limit for the friction state the values chatter but stay bounded;
        // their derivatives do not, and the point says so (its readings stand)
        let mut coarse = c.clone();
        coarse.method = RK4;
        coarse.record_every = 50;
        coarse.t_end = 2e-3;
        let r = run_batch(&coarse, &sp[2..], &AtomicBool::new(false), &AtomicUsize::new(0)).unwrap();
        assert_eq!(r[0].metrics.status, Status::Ok);
        assert!(
            r[0].reason.contains("stability limit of the friction state"),
            "{}",
            r[0].reason
        );
        // a name that is not there makes the point invalid, with the reason
        c.sensitivities = vec!["tau_amp".into()];
        let r = run_batch(&c, &sp[..1], &AtomicBool::new(false), &AtomicUsize::new(0)).unwrap();
        assert_eq!(r[0].metrics.status, Status::Invalid);
        assert!(r[0].reason.contains("'tau_amp'"), "{}", r[0].reason);
        c.record_every = 0;
        assert!(c.validate().unwrap_err().contains("record_every"));
    }

    #[test]
    fn derivatives_alone_equal_those_taken_after_the_run_bitwise() {
        let mut c = cfg(Method::Rk4 { dt: 5e-9 }, Structure::Lps);
        c.record_every = 200;
        c.t_end = 0.5e-3;
        c.sensitivities = ["mu_k", "m2", "k_ground"].iter().map(|s| s.to_string()).collect();
        let mut sp = specs(3);
        sp[1].effects.k_ground = 500.0;
        let full = run_batch(&c, &sp, &AtomicBool::new(false), &AtomicUsize::new(0)).unwrap();
        let mut alone = c.clone();
        alone.derivatives_only = true;
        let r = run_batch(&alone, &sp, &AtomicBool::new(false), &AtomicUsize::new(0)).unwrap();
        for (a, f) in r.iter().zip(&full) {
            assert_eq!(a.metrics.status, Status::Ok);
            assert!(a.trace.is_empty(), "the plain run is not repeated");
            assert_eq!(a.metrics.dt_used, 5e-9);
            assert!(!f.sensitivities.is_empty());
            let bits = |v: &[f64]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
            assert_eq!(bits(&a.sensitivities), bits(&f.sensitivities));
        }
        // a pass that fails says why, its derivatives empty (the caller's readings stand)
        let mut coarse = alone.clone();
        coarse.method = RK4;
        coarse.record_every = 50;
        coarse.t_end = 2e-3;
        let r = run_batch(&coarse, &sp[2..], &AtomicBool::new(false), &AtomicUsize::new(0)).unwrap();
        assert!(
            r[0].reason.contains("stability limit of the friction state"),
            "{}",
            r[0].reason
        );
        assert!(r[0].sensitivities.is_empty());
        // nothing to differentiate is refused
        alone.sensitivities.clear();
        assert!(alone.validate().unwrap_err().contains("derivatives_only"));
    }

    #[test]
    fn every_fixed_step_method_keeps_itself_through_retries_and_derivative_passes() {
        use crate::integrate::method::METHODS;
        use crate::sensitivity::{derivatives, parse_seeds, Schedule};
        // a point that diverges at the step asked is retried at half of it with the method asked
        // (readings, final state and derivatives equal a run of that method at that step), and
        // each method is asked by its declaration, so a new fixed-step method is covered here
        for decl in METHODS.iter().filter(|d| !d.adaptive) {
            let asked = Method::from_name(decl.name, 4e-7, 1e-6, 1e-6, 1e-9).unwrap();
            let mut c = cfg(asked, Structure::Lps);
            c.record_every = 10;
            c.sensitivities = vec!["mu_k".into()];
            let sp = specs(3);
            let r = run_batch(&c, &sp, &AtomicBool::new(false), &AtomicUsize::new(0)).unwrap();
            let mut retried = 0;
            for (s, o) in sp.iter().zip(&r).filter(|(_, o)| o.metrics.status == Status::Retried) {
                retried += 1;
                let used = asked.with_step(o.metrics.dt_used).unwrap();
                assert_eq!(used.fixed_step(), Some(o.metrics.dt_used), "{}", decl.name);
                assert!(o.metrics.dt_used < 4e-7);
                let every = c.record_every * (4e-7 / o.metrics.dt_used).round() as usize;
                let model = Model::new(s.params, s.effects, Structure::Lps, true, false).unwrap();
                let t = crate::simulate::simulate(&model, &s.wave, 0.0, c.t_end, &model.rest_state(), &used, every)
                    .unwrap();
                assert_eq!(o.trace, t.reading, "{}", decl.name);
                assert_eq!(o.metrics.final_position, t.final_state[0], "{}", decl.name);
                let seeds = parse_seeds(&model, &c.sensitivities, false).unwrap();
                let schedule = Schedule {
                    every,
                    also_last: false,
                };
                let held = Default::default();
                let never = AtomicBool::new(false);
                let (t_end, y0) = (c.t_end, model.rest_state());
                match derivatives(
                    &model, &s.wave, 0.0, t_end, &y0, &used, &held, schedule, &seeds, false, &never,
                ) {
                    Some(Ok(d)) => {
                        let bits = |v: &[f64]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
                        assert_eq!(bits(&o.sensitivities), bits(&d.readings), "{}", decl.name);
                    }
                    Some(Err(e)) => assert!(o.reason.ends_with(&format!("sensitivities: {e}")), "{}", o.reason),
                    None => unreachable!("not cancelled"),
                }
            }
            assert!(retried > 0, "{}: no point was retried", decl.name);
        }
    }

    fn nt_of(o: &PointOutput) -> usize {
        o.trace.len()
    }
}
