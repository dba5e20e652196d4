//! Parameter sensitivities from the engine: the exact derivative of a run's recorded readings
//! (and of its final state) with respect to Table 1 parameters, effect parameters and
//! components of the initial state, by forward-mode dual numbers carried through the same
//! right-hand side and the same integrator as the plain run (`numbers/scalar.rs`). RK4 takes the same
//! fixed steps; an adaptive method is run again with the steps the plain run accepted held
//! (`AdaptiveOptions::held`), so what comes back is the derivative of that discrete solution,
//! step sizes fixed — not a finite difference.
//!
//! At the kinks of the friction law (|v1| at v1 = 0, |dg/dt|, sgn Fh) and the saturation of a
//! servo rig the derivative is that of the branch the run took (one-sided); a state sitting
//! exactly on a kink for a finite time (the rest state before the drive starts) contributes
//! nothing through it.

use std::sync::atomic::{AtomicBool, Ordering};

use num_dual::{Dual64, DualSVec64};
use rayon::prelude::*;

use crate::drive::run_tasks_one_by_one;
use crate::error::InputError;
use crate::integrate::method::Method;
use crate::integrate::stepper::Held;
use crate::integrate::task::{LaneEnd, Observer, SimError, Task};
use crate::model::Model;
use crate::numbers::lane_real::Lanewise;
use crate::numbers::real::Real;
use crate::numbers::scalar::Seedable as Dual;
use crate::numbers::tangent::Tangent;
use crate::physics::effects::{EFFECTS, EFFECT_NAMES, LAGS};
use crate::physics::params::PARAM_NAMES;
use crate::physics::waveform::PiecewiseLinear;

mod tangent_pass;
use tangent_pass::TangentRun;

/// Widest dual number one pass carries; more names take several passes.
pub const MAX_PER_PASS: usize = 8;
/// For the adaptive methods (num-dual's numbers through the generic driver), up to this many
/// names (in a group of 8) run as one scalar dual pass each.
pub const SCALAR_PASSES_UP_TO: usize = 3;

/// The width of the RK4 tangent pass that carries `k` names (1 to [`MAX_PER_PASS`]): the
/// narrowest of 1, 2, 4 and 8 that holds them. A pass costs what its width costs, not what its
/// names do (in plain runs, the paper's LPS / DPS 4: 1.4 / 1.8 at width 1, 1.4 / 1.9 at 2,
/// 2.1 / 3.6 at 4, 3.1 / 4.7 at 8; num-dual's scalar dual through the generic driver 1.7 / 2.2;
/// benches/RESULTS.md §70), and a narrower pass beside a wider one costs more than the wider
/// one alone (5 names: 4 + 1 wide 3.5 / 5.4).
fn tangent_width(k: usize) -> usize {
    k.next_power_of_two().min(MAX_PER_PASS)
}

/// A value a derivative is taken with respect to.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Seed {
    /// a Table 1 parameter
    Param(&'static str),
    /// an effect parameter
    Effect(&'static str),
    /// a component of the initial state (its index in the layout)
    State(usize),
    /// the sampled external force at its knot k (`f_ext[k]`)
    ForceKnot(usize),
}

/// The knot `k` a name `f_ext[k]` asks for, if it is one.
fn force_knot(name: &str) -> Option<Result<usize, InputError>> {
    let inner = name.strip_prefix("f_ext[")?.strip_suffix(']')?;
    Some(
        inner
            .parse::<usize>()
            .map_err(|_| crate::input!("sensitivity '{name}': the knot must be a whole number, as f_ext[12]")),
    )
}

impl Seed {
    fn names(&self, name: &str) -> bool {
        matches!(self, Seed::Param(n) | Seed::Effect(n) if *n == name)
    }
}

/// The seeds for `names` (Table 1 names, effect names, state component names such as `q0`,
/// `v0`, `fh`), refused with the reason when one cannot be differentiated: unknown, repeated,
/// the normal force while it is derived from the masses, or a lag time constant of an effect
/// that is off (the model has no state for it).
pub fn parse_seeds(model: &Model, names: &[String], normal_force_derived: bool) -> Result<Vec<Seed>, InputError> {
    let components = model.layout.components();
    let mut seeds = Vec::with_capacity(names.len());
    for (i, name) in names.iter().enumerate() {
        if names[..i].contains(name) {
            return Err(crate::input!("sensitivity '{name}' is asked for twice"));
        }
        let seed = if let Some(n) = PARAM_NAMES.iter().find(|n| **n == name.as_str()) {
            if *n == "normal_force" && normal_force_derived {
                return Err(
                    "sensitivity 'normal_force': the normal force is derived from the masses here \
                            ((m1 + m2 + mPE) g, and its derivative follows theirs); give normal_force a value \
                            to take a derivative with respect to it"
                        .into(),
                );
            }
            Seed::Param(n)
        } else if let Some(n) = EFFECT_NAMES.iter().find(|n| **n == name.as_str()) {
            // a parameter of a lag effect that is off: the model has no state for it
            let owner = EFFECTS.iter().find(|x| x.params.iter().any(|p| p.name == *n));
            let lag = owner.and_then(|x| LAGS.iter().find(|l| l.effect == x.id));
            if lag.is_some_and(|l| model.effects.value_of(l.tau) == Some(0.0)) {
                return Err(crate::input!(
                    "sensitivity '{n}': its effect is off (a time constant of 0 removes the effect's state); \
                     give the time constant a positive value to take a derivative"
                ));
            }
            Seed::Effect(n)
        } else if let Some(c) = components.iter().position(|(n, _)| n == name) {
            Seed::State(c)
        } else if let Some(k) = force_knot(name) {
            let k = k?;
            let knots = model.external.as_ref().map_or(0, |x| x.len());
            if k >= knots {
                return Err(InputError(if knots == 0 {
                    format!("sensitivity '{name}': the run has no external force; give one to take derivatives with respect to its samples")
                } else {
                    format!(
                        "sensitivity '{name}': the external force has {knots} samples (f_ext[0] .. f_ext[{}])",
                        knots - 1
                    )
                }));
            }
            Seed::ForceKnot(k)
        } else {
            return Err(crate::input!(
                "unknown sensitivity '{name}': name a Table 1 parameter ({}), an effect parameter ({}), a \
                 component of the initial state ({}) or a sample of the external force (f_ext[k])",
                PARAM_NAMES.join(", "),
                EFFECT_NAMES.join(", "),
                components
                    .iter()
                    .map(|(n, _)| n.as_str())
                    .collect::<Vec<_>>()
                    .join(", ")
            ));
        };
        seeds.push(seed);
    }
    Ok(seeds)
}

/// When readings are recorded: at the start, every `every` accepted steps, and at the last step
/// when `also_last` (as `simulate` saves; the batch's recorded readings do not add the last).
#[derive(Clone, Copy, Debug)]
pub struct Schedule {
    pub every: usize,
    pub also_last: bool,
}

/// The derivatives of one run, for `names` seeds in order.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Derivatives {
    pub names: usize,
    /// d reading / d seed at every recorded time, row-major [time][seed] [m per unit]
    pub readings: Vec<f64>,
    /// d final state / d seed, row-major [component][seed]
    pub final_state: Vec<f64>,
}

/// The derivatives of `model`'s run (the plain run's settings: input, span, initial state,
/// method) with respect to `seeds`. `held`: for an adaptive method, the steps the plain run
/// accepted. `None` if cancelled.
#[allow(clippy::too_many_arguments)]
pub fn derivatives(
    model: &Model,
    wave: &PiecewiseLinear,
    t_start: f64,
    t_end: f64,
    y0: &[f64],
    method: &Method,
    held: &Held,
    schedule: Schedule,
    seeds: &[Seed],
    normal_force_derived: bool,
    cancel: &AtomicBool,
) -> Option<Result<Derivatives, SimError>> {
    if !method.is_fixed() && held.is_empty() {
        return Some(Err(SimError::Input(
            "sensitivities of an adaptive run need the steps the run accepted".into(),
        )));
    }
    let n = seeds.len();
    let dim = model.layout.dim;
    let mut out = Derivatives {
        names: n,
        readings: Vec::new(),
        final_state: vec![0.0; dim * n],
    };
    // Passes: groups of up to 8 names, each on a tangent as wide as it needs for RK4; for an
    // adaptive method on num-dual's 8-wide dual vectors, but a group of at most
    // SCALAR_PASSES_UP_TO names as one scalar dual pass per name, which is cheaper there
    // (measured: benches/RESULTS.md, section 7; the vector type pays for its generality). Every
    // width gives the same bits (IEEE operations, num-dual's formulas term for term; a
    // discovery device's whole diagnosis is identical on both rules: RESULTS §71).
    let chunks = seeds.chunks(MAX_PER_PASS);
    let groups: Vec<&[Seed]> = match *method {
        Method::Rk4 { .. } => chunks.collect(),
        Method::Dopri5 { .. } | Method::Rodas4 { .. } | Method::Auto { .. } => chunks
            .flat_map(|c| {
                if c.len() <= SCALAR_PASSES_UP_TO {
                    c.chunks(1).collect()
                } else {
                    vec![c]
                }
            })
            .collect(),
    };
    // the groups side by side (each pass its own; a point's groups are as many tasks for the
    // batch's threads as its points, which matters for a fit's few experiments), taken in order
    let passes: Vec<Option<Result<PassOutput, SimError>>> = groups
        .par_iter()
        .map(|group| {
            let run = Pass {
                model,
                wave,
                t_start,
                t_end,
                y0,
                method,
                held,
                schedule,
                seeds: group,
                normal_force_derived,
            };
            match *method {
                // each fixed-step method names its tangent pass (a new one must add its own)
                Method::Rk4 { dt } => match tangent_width(group.len()) {
                    1 => run.go_tangent::<1>(dt, cancel),
                    2 => run.go_tangent::<2>(dt, cancel),
                    4 => run.go_tangent::<4>(dt, cancel),
                    _ => run.go_tangent::<MAX_PER_PASS>(dt, cancel),
                },
                Method::Dopri5 { .. } | Method::Rodas4 { .. } | Method::Auto { .. } => match group.len() {
                    1 => run.go::<Dual64>(cancel),
                    _ => run.go::<DualSVec64<MAX_PER_PASS>>(cancel),
                },
            }
        })
        .collect();
    let mut first = 0;
    for (group, pass) in groups.iter().zip(passes) {
        let (readings, fin) = match pass? {
            Ok(x) => x,
            Err(e) => return Some(Err(e)),
        };
        let k = group.len();
        let times = readings.len() / k;
        if out.readings.is_empty() {
            out.readings = vec![0.0; times * n];
        }
        for t in 0..times {
            out.readings[t * n + first..t * n + first + k].copy_from_slice(&readings[t * k..(t + 1) * k]);
        }
        for c in 0..dim {
            out.final_state[c * n + first..c * n + first + k].copy_from_slice(&fin[c * k..(c + 1) * k]);
        }
        first += k;
    }
    Some(Ok(out))
}

/// One forward-mode pass over up to [`MAX_PER_PASS`] seeds.
struct Pass<'a> {
    model: &'a Model,
    wave: &'a PiecewiseLinear,
    t_start: f64,
    t_end: f64,
    y0: &'a [f64],
    method: &'a Method,
    held: &'a Held,
    schedule: Schedule,
    seeds: &'a [Seed],
    normal_force_derived: bool,
}

/// Readings' and final state's derivatives of one pass, row-major [time or component][seed].
type PassOutput = (Vec<f64>, Vec<f64>);

impl Pass<'_> {
    /// The model with the seeds lifted to `D`, and the initial state likewise.
    fn lifted<D: Dual>(&self) -> Result<(Model<D>, Vec<D>), SimError> {
        let m = self.model;
        let seeds = self.seeds;
        let lift = |name: &str, v: f64| match seeds.iter().position(|s| s.names(name)) {
            Some(j) => D::seed(v, j),
            None => D::from(v),
        };
        let mut dual = Model::build(
            m.params,
            m.effects,
            m.structure,
            m.hysteresis.is_some(),
            m.layout.accounting.is_some(),
            lift,
            self.normal_force_derived,
        )
        .map_err(SimError::from)?;
        dual.external = m.external.as_ref().map(|x| {
            x.lift(|k, v| match seeds.iter().position(|s| *s == Seed::ForceKnot(k)) {
                Some(j) => D::seed(v, j),
                None => D::from(v),
            })
        });
        let y0: Vec<D> = self
            .y0
            .iter()
            .enumerate()
            .map(|(c, &x)| match seeds.iter().position(|s| *s == Seed::State(c)) {
                Some(j) => D::seed(x, j),
                None => D::from(x),
            })
            .collect();
        Ok((dual, y0))
    }

    fn recorder<'m, D: Carries>(&self, model: &'m Model<D>) -> Recorder<'m, D> {
        Recorder {
            model,
            halt: None,
            schedule: self.schedule,
            until: self.schedule.every,
            k: self.seeds.len(),
            out: Vec::new(),
            blew_up: None,
            v_peak: 0.0,
        }
    }

    /// A pass through the generic drivers, on num-dual's numbers (any method). The driver
    /// watches a flag of the pass's own, which the recorder raises when the caller cancels or
    /// when a derivative stops being finite (the rest of such a pass would be thrown away).
    fn go<D: Dual>(&self, cancel: &AtomicBool) -> Option<Result<PassOutput, SimError>> {
        let (dual, y0) = match self.lifted::<D>() {
            Ok(x) => x,
            Err(e) => return Some(Err(e)),
        };
        let task = Task {
            model: &dual,
            wave: self.wave,
            t_start: self.t_start,
            t_end: self.t_end,
            y0: &y0,
        };
        let stop = AtomicBool::new(cancel.load(Ordering::Relaxed));
        let mut rec = self.recorder(&dual);
        rec.halt = Some((cancel, &stop));
        let Some(mut ends) = run_tasks_one_by_one(&[task], self.method, self.held, &mut rec, &stop) else {
            return match rec.blew_up {
                Some(t) if !cancel.load(Ordering::Relaxed) => {
                    Some(Err(unbounded(self.model, t, rec.v_peak, self.method)))
                }
                _ => None,
            };
        };
        let (end, y) = ends.pop().expect("one task");
        Some(self.finish(rec, end, &y))
    }

    /// An RK4 pass on [`Tangent`] numbers (the model built on num-dual's, then converted):
    /// the same values and derivatives as [`Pass::go`] on `DualSVec64<K>`, several times
    /// faster, and stopped at the first derivative that is not finite (the rest of such a pass
    /// is thrown away).
    fn go_tangent<const K: usize>(&self, dt: f64, cancel: &AtomicBool) -> Option<Result<PassOutput, SimError>> {
        let (dual, y0) = match self.lifted::<DualSVec64<K>>() {
            Ok(x) => x,
            Err(e) => return Some(Err(e)),
        };
        let model: Model<Tangent<K>> = Lanewise::splat(&dual);
        let y0: Vec<Tangent<K>> = y0.iter().map(Lanewise::splat).collect();
        let mut rec = self.recorder(&model);
        let run = TangentRun {
            model: &model,
            wave: self.wave,
            t_start: self.t_start,
            t_end: self.t_end,
            y0: &y0,
            dt,
            rec: &mut rec,
            cancel,
        };
        let (end, y) = crate::lanes::simd_arch().dispatch(run)?;
        Some(self.finish(rec, end, &y))
    }

    /// The pass's output from how its run ended.
    fn finish<D: Carries>(&self, rec: Recorder<D>, end: LaneEnd, y: &[D]) -> Result<PassOutput, SimError> {
        match end {
            LaneEnd::Finished { .. } if rec.blew_up.is_some() => {
                Err(unbounded(self.model, rec.blew_up.unwrap_or_default(), rec.v_peak, self.method))
            }
            LaneEnd::Finished { .. } => {
                let k = self.seeds.len();
                let mut fin = vec![0.0; y.len() * k];
                let mut d = [0.0; MAX_PER_PASS];
                for (c, yc) in y.iter().enumerate() {
                    yc.parts(&mut d[..D::WIDTH]);
                    fin[c * k..(c + 1) * k].copy_from_slice(&d[..k]);
                }
                Ok((rec.out, fin))
            }
            LaneEnd::Diverged { t, why, .. } => Err(SimError::Diverged {
                t,
                message: format!(
                    "the derivative pass left the plain run's path at t = {t:.6e} s ({}); use a smaller dt or tighter tolerances",
                    why.unwrap_or_else(|| "its state left the model's bounds".into())
                ),
            }),
        }
    }
}

/// A number a pass records: a value and `WIDTH` derivative parts.
pub trait Carries: Real<Value = f64> {
    const WIDTH: usize;
    /// The derivative parts, into `out` (length `WIDTH`).
    fn parts(&self, out: &mut [f64]);
}

impl<D: Dual> Carries for D {
    const WIDTH: usize = <D as Dual>::WIDTH;
    fn parts(&self, out: &mut [f64]) {
        self.derivatives(out)
    }
}

impl<const K: usize> Carries for Tangent<K> {
    const WIDTH: usize = K;
    fn parts(&self, out: &mut [f64]) {
        out.copy_from_slice(&self.eps)
    }
}

/// The error of a pass whose derivatives stopped being finite at `t` [s]: with RK4, a step
/// beyond the stability limit of the friction state while sliding at up to `v_peak` [m/s].
/// The run's values stay bounded there (the friction law saturates them) but chatter from step
/// to step, and the derivative of that chatter grows without bound.
fn unbounded(model: &Model, t: f64, v_peak: f64, method: &Method) -> SimError {
    let hint = match method.fixed_step() {
        Some(dt) => {
            let limit = crate::integrate::plan::RK4_STABLE_OMEGA_DT / model.friction.sliding_stiffness(v_peak);
            format!(
                "dt = {dt:e} s is beyond the stability limit of the friction state while sliding at up to {v_peak:.3e} m/s \
                 (dt <= {limit:.2e} s): the run's values stay bounded by the friction law's saturation but chatter \
                 from step to step, and their derivatives grow without bound; use a smaller dt"
            )
        }
        _ => "use tighter tolerances".into(),
    };
    SimError::Diverged {
        t,
        message: format!("the derivatives are not finite from t = {t:.6e} s: {hint}"),
    }
}

/// Records the first `k` derivatives of the reading on the schedule of the plain run's saver,
/// the first time a derivative is not finite, and the peak |v1| [m/s].
struct Recorder<'a, D: Carries> {
    model: &'a Model<D>,
    /// (the caller's cancel flag, the flag the driver watches): raise the second when the
    /// first is raised or a derivative blew up
    halt: Option<(&'a AtomicBool, &'a AtomicBool)>,
    schedule: Schedule,
    until: usize,
    k: usize,
    out: Vec<f64>,
    blew_up: Option<f64>,
    v_peak: f64,
}

impl<D: Carries> Recorder<'_, D> {
    fn record(&mut self, t: f64, y: &[D]) {
        let mut d = [0.0; MAX_PER_PASS];
        self.model.reading(t, y).parts(&mut d[..D::WIDTH]);
        if self.blew_up.is_none() && d.iter().any(|x| !x.is_finite()) {
            self.blew_up = Some(t);
        }
        self.out.extend_from_slice(&d[..self.k]);
    }

    /// An accepted step ending at `t` [s] in state `y`; `last` marks the run's final step.
    fn on_step(&mut self, t: f64, y: &[D], last: bool) {
        self.v_peak = self.v_peak.max(y[self.model.layout.dof].value().abs());
        self.until -= 1;
        if self.until == 0 || (last && self.schedule.also_last) {
            self.record(t, y);
            self.until = self.schedule.every;
        }
        if let Some((outer, stop)) = self.halt {
            if self.blew_up.is_some() || outer.load(Ordering::Relaxed) {
                stop.store(true, Ordering::Relaxed);
            }
        }
    }
}

impl<D: Dual> Observer<D> for Recorder<'_, D> {
    fn start(&mut self, _task: usize, t: f64, y: &[D]) {
        self.record(t, y);
    }

    fn step(&mut self, _task: usize, t: f64, _span: f64, y: &[D], _v: f64, _s: Option<(D, D)>, last: bool) {
        self.on_step(t, y, last);
    }
}

#[cfg(test)]
mod tests;
