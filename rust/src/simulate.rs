//! One run, saved: the driver (`drive/`) with a [`Trajectory`] as its observer. From rest or
//! from any state, by RK4 or an adaptive method; the final state comes back so a run can be
//! continued or restarted mid-record.

use std::sync::atomic::AtomicBool;

use crate::drive::run_tasks;
use crate::integrate::crawl::CRAWL_PREFIX;
use crate::integrate::method::Method;
use crate::integrate::plan::divergence_message;
use crate::integrate::stepper::Held;
use crate::integrate::task::{LaneEnd, Observer, SimError, Task};
use crate::model::Model;
use crate::physics::waveform::PiecewiseLinear;
use crate::sensitivity::{derivatives, Derivatives, Schedule, Seed};

/// Saved trajectory; each per-time array has one entry per saved time.
#[derive(Clone, Debug, Default)]
pub struct Trajectory {
    pub dof: usize,
    pub t: Vec<f64>,
    /// nodal displacements, row-major [time][node] [m]
    pub nodes: Vec<f64>,
    /// nodal velocities, row-major [time][node] [m/s]
    pub velocities: Vec<f64>,
    pub g: Vec<f64>,
    pub fh: Vec<f64>,
    pub h: Vec<f64>,
    /// friction force Ff [N]
    pub friction: Vec<f64>,
    /// piezo force Fp [N]
    pub piezo_force: Vec<f64>,
    /// commanded voltage [V]
    pub voltage: Vec<f64>,
    /// sensor reading [m] (x1 unless a sensor effect is on)
    pub reading: Vec<f64>,
    /// accounting states per saved time, row-major [time][N_ACCOUNTING]; empty unless asked
    pub accounting: Vec<f64>,
    /// kinetic and strain energy per saved time [J]; empty unless accounting
    pub kinetic: Vec<f64>,
    pub strain: Vec<f64>,
    /// momentum 1'Mv per saved time [kg m/s]; empty unless accounting
    pub momentum: Vec<f64>,
    /// the state at t_end
    pub final_state: Vec<f64>,
    /// an adaptive run's accepted steps and the states they reached (empty for RK4): held by
    /// a run that carries derivatives along this one (`sensitivity/`)
    pub held: Held,
}

impl Trajectory {
    fn record(&mut self, model: &Model, t: f64, y: &[f64], v_cmd: f64) {
        let l = model.layout;
        let n = l.dof;
        self.t.push(t);
        self.nodes.extend_from_slice(&y[..n]);
        self.velocities.extend_from_slice(&y[n..2 * n]);
        self.g.push(y[l.g]);
        self.fh.push(y[l.fh]);
        self.h.push(y[l.h]);
        self.friction.push(model.friction_force(y));
        self.piezo_force.push(model.piezo_force(v_cmd, y));
        self.voltage.push(v_cmd);
        self.reading.push(model.reading(t, y));
        if let Some(a) = l.accounting {
            self.accounting.extend_from_slice(&y[a..a + crate::model::N_ACCOUNTING]);
            self.kinetic.push(model.mech.kinetic(&y[n..2 * n]));
            self.strain.push(model.mech.strain(&y[..n]));
            self.momentum.push(model.mech.momentum(&y[n..2 * n]));
        }
    }
}

/// Saves a [`Trajectory`] every `save_every` accepted steps, plus the first and last state.
struct Saver<'a> {
    model: &'a Model,
    wave: &'a PiecewiseLinear,
    save_every: usize,
    until_save: usize,
    keep_steps: bool,
    out: Trajectory,
}

impl Observer for Saver<'_> {
    fn start(&mut self, _task: usize, t: f64, y: &[f64]) {
        self.out.record(self.model, t, y, self.wave.value(t));
    }

    #[inline(always)]
    fn accepted_step(&mut self, _task: usize, step: f64) {
        if self.keep_steps {
            self.out.held.steps.push(step);
        }
    }

    fn switched(&mut self, _task: usize, accepted: u64) {
        if self.keep_steps {
            self.out.held.switches.push(accepted);
        }
    }

    fn step(&mut self, _task: usize, t: f64, _span: f64, y: &[f64], v: f64, _s: Option<(f64, f64)>, last: bool) {
        if self.keep_steps {
            self.out.held.states.extend_from_slice(y);
        }
        self.until_save -= 1; // a countdown, not k % save_every: no division in the step loop
        if self.until_save == 0 || last {
            self.out.record(self.model, t, y, v);
            self.until_save = self.save_every;
        }
    }
}

/// Run `model` under `wave` from `t_start` to `t_end` [s] starting in state `y0` (see
/// [`Model::rest_state`], [`crate::model::Layout::components`]) with `method`, saving every
/// `save_every` accepted steps (and the first and last states). `final_state` holds the state
/// at `t_end`: a run continued from it equals the uninterrupted run (bit for bit with RK4 when
/// the step times coincide, i.e. `t_start` is a multiple of dt).
pub fn simulate(
    model: &Model,
    wave: &PiecewiseLinear,
    t_start: f64,
    t_end: f64,
    y0: &[f64],
    method: &Method,
    save_every: usize,
) -> Result<Trajectory, SimError> {
    let never = AtomicBool::new(false);
    simulate_until(model, wave, t_start, t_end, y0, method, save_every, &never).map(|(traj, _)| traj)
}

/// [`simulate`] that stops soon after `cancel` is set, returning the trajectory saved so far
/// (its `final_state` then empty) and `false` for "not complete".
#[allow(clippy::too_many_arguments)]
pub fn simulate_until(
    model: &Model,
    wave: &PiecewiseLinear,
    t_start: f64,
    t_end: f64,
    y0: &[f64],
    method: &Method,
    save_every: usize,
    cancel: &AtomicBool,
) -> Result<(Trajectory, bool), SimError> {
    simulate_keeping(model, wave, t_start, t_end, y0, method, save_every, false, cancel)
}

/// [`simulate_until`] that also keeps, with `keep_held` and an adaptive method, the steps and
/// states a derivative pass holds (`Trajectory::held`; one state per step).
#[allow(clippy::too_many_arguments)]
pub fn simulate_keeping(
    model: &Model,
    wave: &PiecewiseLinear,
    t_start: f64,
    t_end: f64,
    y0: &[f64],
    method: &Method,
    save_every: usize,
    keep_held: bool,
    cancel: &AtomicBool,
) -> Result<(Trajectory, bool), SimError> {
    if save_every == 0 {
        return Err(SimError::Input("parameter 'save_every' must be at least 1".into()));
    }
    let task = Task {
        model,
        wave,
        t_start,
        t_end,
        y0,
    };
    crate::integrate::plan::check_task(&task, method)?;
    let mut saver = Saver {
        model,
        wave,
        save_every,
        until_save: save_every,
        keep_steps: keep_held && !method.is_fixed(),
        out: Trajectory {
            dof: model.layout.dof,
            ..Default::default()
        },
    };
    let Some(mut ends) = run_tasks::<_, 1>(&[task], method, &mut saver, cancel) else {
        return Ok((saver.out, false));
    };
    let (end, y) = ends.pop().expect("one task");
    match end {
        LaneEnd::Diverged { t, why, v_last } => {
            let message = match (why, method.fixed_step()) {
                (None, Some(dt)) => divergence_message(model, dt, t, &y, v_last, Some((wave, t_start, t_end))),
                (Some(why), _) if why.starts_with(CRAWL_PREFIX) => {
                    format!("integration stopped at t = {t:.6e} s: {why}")
                }
                (why, _) => format!(
                    "integration diverged at t = {t:.6e} s: {}; tighten rtol/atol or use method 'rk4' with a small dt",
                    why.unwrap_or_else(|| "the state is no longer finite".into())
                ),
            };
            Err(SimError::Diverged { t, message })
        }
        LaneEnd::Finished { .. } => {
            if let Some(i) = y.iter().position(|x| !x.is_finite()) {
                return Err(SimError::Diverged {
                    t: t_end,
                    message: format!(
                        "state component '{}' is not finite at the end of the run",
                        model.layout.components()[i].0
                    ),
                });
            }
            let mut out = saver.out;
            out.final_state = y;
            Ok((out, true))
        }
    }
}

/// One run as Python's `simulate()` makes it, stoppable: the trajectory saved every `save_every`
/// steps, whether it ran to `t_end`, and — when `seeds` are asked for and the run completed —
/// the exact derivatives of its readings and final state with respect to them (the run's own
/// steps held). `cancel` stops it between steps; the trajectory so far stands (not complete,
/// no derivatives). The binding runs this on a worker thread and sets `cancel` on Ctrl-C.
#[allow(clippy::too_many_arguments)]
pub fn simulate_with_derivatives(
    model: &Model,
    wave: &PiecewiseLinear,
    t_start: f64,
    t_end: f64,
    y0: &[f64],
    method: &Method,
    save_every: usize,
    seeds: &[Seed],
    normal_force_derived: bool,
    cancel: &AtomicBool,
) -> Result<(Trajectory, bool, Option<Derivatives>), SimError> {
    let keep = !seeds.is_empty();
    let (traj, complete) = simulate_keeping(model, wave, t_start, t_end, y0, method, save_every, keep, cancel)?;
    if !(complete && keep) {
        return Ok((traj, complete, None));
    }
    let schedule = Schedule {
        every: save_every,
        also_last: true,
    };
    match derivatives(
        model,
        wave,
        t_start,
        t_end,
        y0,
        method,
        &traj.held,
        schedule,
        seeds,
        normal_force_derived,
        cancel,
    ) {
        None => Ok((traj, false, None)), // cancelled: the trajectory stands
        Some(d) => Ok((traj, true, Some(d?))),
    }
}

/// Run from rest over [0, `t_end`] with RK4 of step `dt` [s], saving every `save_every` steps:
/// the paper's setting (the shorthand of the Rust tests and `examples/paper_case.rs`; the
/// bindings call `simulate`).
pub fn simulate_from_rest(
    model: &Model,
    wave: &PiecewiseLinear,
    t_end: f64,
    dt: f64,
    save_every: usize,
) -> Result<Trajectory, SimError> {
    simulate(
        model,
        wave,
        0.0,
        t_end,
        &model.rest_state(),
        &Method::Rk4 { dt },
        save_every,
    )
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::physics::effects::Effects;
    use crate::physics::mechanics::Structure;
    use crate::physics::params::Params;

    fn paper(structure: Structure, effects: Effects) -> (Model, PiecewiseLinear) {
        let m = Model::new(Params::paper(), effects, structure, true, false).unwrap();
        (m, PiecewiseLinear::triangle(80.0, 0.5e-3, 9.5e-3, 0.0).unwrap())
    }

    #[test]
    fn rk4_continued_from_the_final_state_equals_the_whole_run_bitwise() {
        let e = Effects {
            tau_sensor: 2e-5,
            ..Default::default()
        };
        for (structure, effects) in [(Structure::Lps, Effects::default()), (Structure::Dps(4), e)] {
            let (m, w) = paper(structure, effects);
            // continued in the fall after the slip of the rise: bitwise equality needs no more
            let rk4 = Method::Rk4 { dt: 2e-8 };
            let whole = simulate(&m, &w, 0.0, 1.5e-3, &m.rest_state(), &rk4, 1000).unwrap();
            let a = simulate(&m, &w, 0.0, 0.7e-3, &m.rest_state(), &rk4, 1000).unwrap();
            let b = simulate(&m, &w, 0.7e-3, 1.5e-3, &a.final_state, &rk4, 1000).unwrap();
            assert_eq!(b.final_state, whole.final_state);
            assert_eq!(b.t[0], 0.7e-3);
            assert_eq!(*b.reading.last().unwrap(), *whole.reading.last().unwrap());
        }
    }

    #[test]
    fn dopri5_single_run_agrees_with_rk4_to_a_nanometre() {
        let (m, w) = paper(Structure::Lps, Effects::default());
        // RK4 at dt 2e-8 is within 1e-14 m of dt 1e-8 here: a reference far below the nanometre
        let rk4 = simulate(&m, &w, 0.0, 10e-3, &m.rest_state(), &Method::Rk4 { dt: 2e-8 }, 500).unwrap();
        let ad = Method::Dopri5 {
            rtol: 1e-8,
            atol: 1e-8,
            first_step: 1e-8,
        };
        let d = simulate(&m, &w, 0.0, 10e-3, &m.rest_state(), &ad, 100).unwrap();
        assert!((d.final_state[0] - rk4.final_state[0]).abs() < 1e-9);
        assert_eq!(*d.t.last().unwrap(), 10e-3);
        assert!(d.t.len() < rk4.t.len(), "{} saves", d.t.len());
        // and continued mid-record from its own final state
        let a = simulate(&m, &w, 0.0, 4e-3, &m.rest_state(), &ad, 100).unwrap();
        let b = simulate(&m, &w, 4e-3, 10e-3, &a.final_state, &ad, 100).unwrap();
        assert!((b.final_state[0] - rk4.final_state[0]).abs() < 1e-9);
    }

    #[test]
    fn rodas4_agrees_with_rk4_to_a_nanometre_in_far_fewer_steps() {
        let lag = Effects {
            tau_amp: 1e-5,
            tau_sensor: 2e-5,
            k_ground: 500.0,
            ..Default::default()
        };
        let ro = Method::Rodas4 {
            rtol: 1e-6,
            atol: 1e-6,
            first_step: 1e-8,
        };
        for (structure, effects) in [
            (Structure::Lps, Effects::default()),
            (Structure::Dps(4), Effects::default()),
            (Structure::Lps, lag),
        ] {
            let (m, w) = paper(structure, effects);
            // the reference at dt 2e-8: within 4e-14 m of dt 1e-8 on each of these
            let rk4 = simulate(&m, &w, 0.0, 10e-3, &m.rest_state(), &Method::Rk4 { dt: 2e-8 }, 500).unwrap();
            let d = simulate(&m, &w, 0.0, 10e-3, &m.rest_state(), &ro, 1).unwrap();
            assert!((d.final_state[0] - rk4.final_state[0]).abs() < 1e-9, "{structure:?}");
            assert!(d.t.len() < 1_000_000 / 100, "{} steps", d.t.len());
        }
    }

    /// The near-frictionless device: mu 1e-6, LPS, 1 ms of a 50 V triangle.
    fn near_frictionless() -> (Model, PiecewiseLinear) {
        let mut p = Params::paper();
        p.mu_k = 1e-6;
        p.mu_s = 1e-6;
        let m = Model::new(p, Effects::default(), Structure::Lps, true, false).unwrap();
        (m, PiecewiseLinear::triangle(50.0, 0.5e-3, 0.5e-3, 0.0).unwrap())
    }

    #[test]
    fn an_explicit_run_held_at_its_stability_limit_stops_with_a_message_instead_of_crawling() {
        // it ran for more than a minute without a word; Rodas4 takes 2.5 ms
        let (m, w) = near_frictionless();
        let dp = Method::Dopri5 {
            rtol: 3e-7,
            atol: 3e-7,
            first_step: 1e-8,
        };
        let err = simulate(&m, &w, 0.0, 1e-3, &m.rest_state(), &dp, 100)
            .unwrap_err()
            .to_string();
        assert!(err.starts_with("integration stopped at t = "), "{err}");
        assert!(
            err.contains(crate::integrate::crawl::CRAWL_PREFIX)
                && err.contains("stability limit")
                && err.contains("'rodas4'"),
            "{err}"
        );
        // once its pace projects more than 1e8 (the step shrinks as the contact speeds up: after
        // 0.74 M steps here, a quarter of a second), not after the 2e8 the run would take
        let so_far: u64 = err
            .split(" steps so far")
            .next()
            .and_then(|s| s.rsplit(' ').next())
            .and_then(|s| s.parse().ok())
            .expect("the message counts the steps");
        assert!(so_far < 2_000_000, "{err}");
        let ro = Method::Rodas4 {
            rtol: 1e-6,
            atol: 1e-6,
            first_step: 1e-8,
        };
        let r = simulate(&m, &w, 0.0, 1e-3, &m.rest_state(), &ro, 100).expect("Rodas4 runs it");
        assert!(r.final_state.iter().all(|x| x.is_finite()));
    }

    #[test]
    fn rodas4_takes_steps_set_by_accuracy_where_friction_is_stiff() {
        // a light weight at a high voltage: long sliding phases where the presliding state is
        // stiff; the explicit method is held at its stability limit there, Rodas4 is not
        let mut p = Params::paper();
        p.m2 = 0.25 * p.m1;
        p.normal_force = p.default_normal_force();
        let m = Model::new(p, Effects::default(), Structure::Lps, true, false).unwrap();
        let w = PiecewiseLinear::triangle(98.0, 0.5e-3, 9.5e-3, 0.0).unwrap();
        let steps = |method: Method| {
            simulate(&m, &w, 0.0, 10e-3, &m.rest_state(), &method, 1)
                .unwrap()
                .t
                .len()
                - 1
        };
        let (tol, h) = (1e-6, 1e-8);
        let ro = steps(Method::Rodas4 {
            rtol: tol,
            atol: tol,
            first_step: h,
        });
        let dp = steps(Method::Dopri5 {
            rtol: tol,
            atol: tol,
            first_step: h,
        });
        assert!(3 * ro < dp, "rodas4 {ro} steps, dopri5 {dp}");
    }

    #[test]
    fn auto_changes_a_stiff_run_to_rodas4_and_keeps_a_plain_one_explicit() {
        let auto = Method::Auto {
            rtol: 3e-7,
            atol: 3e-7,
            first_step: 1e-8,
        };
        let (m, w) = near_frictionless();
        let (a, _) = simulate_keeping(
            &m,
            &w,
            0.0,
            1e-3,
            &m.rest_state(),
            &auto,
            1,
            true,
            &AtomicBool::new(false),
        )
        .unwrap();
        let at = *a.held.switches.first().expect("the near-frictionless run switches");
        assert!(
            a.held.switches.len() % 2 == 1,
            "and ends implicit: {:?}",
            a.held.switches
        );
        // after TRY_IMPLICIT_AFTER steps at the stability limit (measured: 467)
        assert!(
            at < 3 * crate::integrate::stiffness::TRY_IMPLICIT_AFTER as u64,
            "switched after {at} steps"
        );
        let steps = a.t.len() - 1;
        assert!(steps < 20_000, "{steps} steps");
        let tight = Method::Rodas4 {
            rtol: 1e-9,
            atol: 1e-9,
            first_step: 1e-9,
        };
        let r = simulate(&m, &w, 0.0, 1e-3, &m.rest_state(), &tight, 1).unwrap();
        assert!(
            (a.final_state[0] - r.final_state[0]).abs() < 1e-9,
            "{} vs {}",
            a.final_state[0],
            r.final_state[0]
        );
        // the paper case is stiff for moments only: it may take Rodas4 for a stretch and must come
        // back (without the recheck it stayed on Rodas4 and took 6,160 steps, 2.7x the time)
        let (m, w) = paper(Structure::Lps, Effects::default());
        let (a, _) = simulate_keeping(
            &m,
            &w,
            0.0,
            10e-3,
            &m.rest_state(),
            &auto,
            1,
            true,
            &AtomicBool::new(false),
        )
        .unwrap();
        let dp = Method::Dopri5 {
            rtol: 3e-7,
            atol: 3e-7,
            first_step: 1e-8,
        };
        let d = simulate(&m, &w, 0.0, 10e-3, &m.rest_state(), &dp, 1).unwrap();
        let sw = &a.held.switches;
        assert!(sw.len() % 2 == 0, "ends on Dormand-Prince: {sw:?}");
        // implicit steps, between each switch to Rodas4 and the next back
        let implicit: u64 = sw.chunks(2).map(|p| p[1] - p[0]).sum();
        let (steps, explicit_steps) = ((a.t.len() - 1) as u64, (d.t.len() - 1) as f64);
        let cost = (steps - implicit) as f64
            + crate::integrate::stiffness::implicit_step_cost(m.rest_state().len()) * implicit as f64;
        eprintln!("paper auto: switches {sw:?}, {steps} steps ({implicit} implicit), dopri5 {explicit_steps}");
        assert!(
            cost < 1.2 * explicit_steps,
            "{cost} Dormand-Prince steps' worth against {explicit_steps}"
        );
        assert!((a.final_state[0] - d.final_state[0]).abs() < 1e-9);
    }

    #[test]
    fn bad_initial_states_and_spans_are_refused_by_name() {
        let (m, w) = paper(Structure::Lps, Effects::default());
        let rk4 = Method::Rk4 { dt: 1e-8 };
        let err = |y: &[f64], t0: f64| simulate(&m, &w, t0, 1e-3, y, &rk4, 10).unwrap_err().to_string();
        assert!(err(&[0.0; 3], 0.0).contains("q0, q1, v0, v1, g, fh, h"));
        let mut y = m.rest_state();
        y[m.layout.fh] = 1e3;
        assert!(err(&y, 0.0).contains("'fh'"));
        y[m.layout.fh] = f64::NAN;
        assert!(err(&y, 0.0).contains("must be finite"));
        assert!(err(&m.rest_state(), 0.5e-8).contains("t_start"));
        assert!(err(&m.rest_state(), 2e-3).contains("t_start"));
    }
}
