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

use crate::drive::run_tasks_one_by_one;
use crate::error::InputError;
use crate::integrate::method::Method;
use crate::integrate::stepper::Held;
use crate::integrate::tableau::{rk4_factor, rk4_sum, RK4_NODES};
use crate::integrate::task::{LaneEnd, Observer, SimError, Task};
use crate::model::Model;
use crate::numbers::lane_real::Lanewise;
use crate::numbers::real::Real;
use crate::numbers::scalar::Seedable as Dual;
use crate::numbers::tangent::Tangent;
use crate::physics::effects::{EFFECTS, EFFECT_NAMES, LAGS};
use crate::physics::params::PARAM_NAMES;
use crate::physics::waveform::{Cursor, PiecewiseLinear};

/// Widest dual number one pass carries; more names take several passes.
pub const MAX_PER_PASS: usize = 8;
/// Up to this many names (in a group of 8) run as one scalar dual pass each.
pub const SCALAR_PASSES_UP_TO: usize = 3;

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
    // Passes: groups of up to 8 names on 8-wide dual vectors, but a group of at most
    // SCALAR_PASSES_UP_TO names as one scalar dual pass per name, which is cheaper there
    // (measured: benches/RESULTS.md, section 7; the vector type pays for its generality).
    let mut first = 0;
    for chunk in seeds.chunks(MAX_PER_PASS) {
        let groups: Vec<&[Seed]> = if chunk.len() <= SCALAR_PASSES_UP_TO {
            chunk.chunks(1).collect()
        } else {
            vec![chunk]
        };
        for group in groups {
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
            let pass = match group.len() {
                1 => run.go::<Dual64>(cancel),
                // each fixed-step method names its tangent pass (a new one must add its own)
                _ => match *method {
                    Method::Rk4 { dt } => run.go_tangent::<MAX_PER_PASS>(dt, cancel),
                    Method::Dopri5 { .. } | Method::Rodas4 { .. } | Method::Auto { .. } => {
                        run.go::<DualSVec64<MAX_PER_PASS>>(cancel)
                    }
                },
            }?;
            let (readings, fin) = match pass {
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

/// [`rk4_pass`] as one operation for `pulp` to compile per instruction set (as the lane
/// drivers are: `drive::PlainGroups`): a tangent's K derivatives are K-wide vector arithmetic,
/// and IEEE operations give the same bits at any width.
struct TangentRun<'r, 'm, const K: usize> {
    model: &'r Model<Tangent<K>>,
    wave: &'r PiecewiseLinear,
    t_start: f64,
    t_end: f64,
    y0: &'r [Tangent<K>],
    dt: f64,
    rec: &'r mut Recorder<'m, Tangent<K>>,
    cancel: &'r AtomicBool,
}

impl<const K: usize> pulp::WithSimd for TangentRun<'_, '_, K> {
    type Output = Option<(LaneEnd, Vec<Tangent<K>>)>;
    #[inline(always)]
    fn with_simd<S: pulp::Simd>(self, _simd: S) -> Self::Output {
        rk4_pass(
            self.model,
            self.wave,
            self.t_start,
            self.t_end,
            self.y0,
            self.dt,
            self.rec,
            self.cancel,
        )
    }
}

/// Fixed-step RK4 of one tangent run, step for step as the generic driver takes it with one
/// lane (`drive::drive_lanes`, `integrate/rk4.rs`): step k from t = k dt, the input through the step from
/// the breakpoint cursor at its midpoint, the four stages and the update in the same order,
/// the same divergence check; the recorder sees each accepted step. Stops early (as
/// `Finished`, with the recorder holding the time) once a recorded derivative is not finite.
/// `None` if cancelled.
#[allow(clippy::too_many_arguments)]
#[inline(always)]
fn rk4_pass<const K: usize>(
    model: &Model<Tangent<K>>,
    wave: &PiecewiseLinear,
    t_start: f64,
    t_end: f64,
    y0: &[Tangent<K>],
    dt: f64,
    rec: &mut Recorder<Tangent<K>>,
    cancel: &AtomicBool,
) -> Option<(LaneEnd, Vec<Tangent<K>>)> {
    let n = y0.len();
    let dof = model.layout.dof;
    let bound = model.presliding_bound() * (1.0 + crate::integrate::rk4::BOUND_SLACK) + 1e-12;
    let mut y = y0.to_vec();
    let zero = Tangent::constant(0.0);
    let (mut k1, mut k2, mut k3, mut k4, mut tmp) = (
        vec![zero; n],
        vec![zero; n],
        vec![zero; n],
        vec![zero; n],
        vec![zero; n],
    );
    let [c1, c2, c3, c4] = RK4_NODES.map(|c| c * dt);
    let factor = rk4_factor(dt);
    let mut k = (t_start / dt).round() as usize;
    let k_end = k + ((t_end - t_start) / dt).round() as usize;
    let mut cursor = Cursor::at(wave, t_start);
    let mut v_last = y[dof].re;
    let mut steps = 0u64;
    rec.record(t_start, &y);
    loop {
        if steps.is_multiple_of(crate::integrate::task::CANCEL_CHECK_ATTEMPTS as u64) && cancel.load(Ordering::Relaxed)
        {
            return None;
        }
        let t0 = k as f64 * dt;
        let probe = t0 + 0.5 * dt;
        cursor.advance(wave, probe);
        let (v0, s) = cursor.input(wave, t0, probe);
        // plain calls, not a closure: code left out of line runs as baseline (see `Real::select`)
        stage_rate(model, t0, v0, s, c1, &y, &mut k1);
        axpy(&mut tmp, &y, c2, &k1);
        stage_rate(model, t0, v0, s, c2, &tmp, &mut k2);
        axpy(&mut tmp, &y, c3, &k2);
        stage_rate(model, t0, v0, s, c3, &tmp, &mut k3);
        axpy(&mut tmp, &y, c4, &k3);
        stage_rate(model, t0, v0, s, c4, &tmp, &mut k4);
        for j in 0..n {
            y[j] += rk4_sum(k1[j], k2[j], k3[j], k4[j]) * factor;
        }
        k += 1;
        let t_new = k as f64 * dt;
        if model.is_diverged(&y, bound) {
            return Some((
                LaneEnd::Diverged {
                    t: t_new,
                    why: None,
                    v_last,
                },
                y,
            ));
        }
        v_last = y[dof].re;
        steps += 1;
        let done = k == k_end;
        rec.on_step(t_new, &y, done);
        if done || rec.blew_up.is_some() {
            return Some((LaneEnd::Finished { steps, min_step: dt }, y));
        }
    }
}

/// The right-hand side at `tau` [s] into the step from `t0` [s], the input `v0 + s tau` [V]
/// (as `integrate::model_rhs::ModelRhs::eval`).
#[inline(always)]
fn stage_rate<const K: usize>(
    model: &Model<Tangent<K>>,
    t0: f64,
    v0: f64,
    s: f64,
    tau: f64,
    y: &[Tangent<K>],
    dy: &mut [Tangent<K>],
) {
    model.rhs_impl::<0, true>(t0 + tau, Tangent::constant(v0 + s * tau), s, y, dy);
}

/// out = y + h k (as `integrate/rk4.rs`)
#[inline(always)]
fn axpy<const K: usize>(out: &mut [Tangent<K>], y: &[Tangent<K>], h: f64, k: &[Tangent<K>]) {
    for j in 0..out.len() {
        out[j] = y[j] + k[j] * h;
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
mod tests {
    use super::*;
    use crate::physics::effects::Effects;
    use crate::physics::mechanics::Structure;
    use crate::physics::params::Params;
    use crate::physics::rig::RigDrive;
    use crate::simulate::simulate_keeping;

    static NEVER: AtomicBool = AtomicBool::new(false);

    /// A device: parameters, effects, structure, input, span, RK4 step or adaptive method.
    #[derive(Clone)]
    struct Case {
        p: Params,
        e: Effects,
        s: Structure,
        hyst: bool,
        wave: PiecewiseLinear,
        t_end: f64,
        method: Method,
        every: usize,
        derived_fn: bool,
    }

    fn paper(s: Structure, e: Effects) -> Case {
        Case {
            p: Params::paper(),
            e,
            s,
            hyst: true,
            wave: PiecewiseLinear::triangle(80.0, 0.5e-3, 9.5e-3, 0.0).unwrap(),
            t_end: 1e-3,
            method: Method::Rk4 { dt: 1e-8 },
            every: 2000,
            derived_fn: false,
        }
    }

    impl Case {
        fn with(&self, name: &str, v: f64) -> Case {
            let mut c = self.clone();
            if c.p.set(name, v).is_err() {
                c.e.set(name, v).unwrap();
            }
            if c.derived_fn {
                c.p.normal_force = c.p.default_normal_force();
            }
            c
        }

        fn model(&self) -> Model {
            Model::new(self.p, self.e, self.s, self.hyst, false).unwrap()
        }

        /// Readings on the saver's schedule, and the steps and states an adaptive run held.
        fn readings(&self, y0: &[f64]) -> (Vec<f64>, Held) {
            let (r, _) = simulate_keeping(
                &self.model(),
                &self.wave,
                0.0,
                self.t_end,
                y0,
                &self.method,
                self.every,
                true,
                &NEVER,
            )
            .unwrap();
            (r.reading, r.held)
        }

        /// The engine's derivatives of the readings, [time][name].
        fn engine(&self, names: &[&str]) -> Vec<f64> {
            let m = self.model();
            let rest = m.rest_state();
            let (base, held) = self.readings(&rest);
            let names_s: Vec<String> = names.iter().map(|s| s.to_string()).collect();
            let seeds = parse_seeds(&m, &names_s, self.derived_fn).unwrap();
            let schedule = Schedule {
                every: self.every,
                also_last: true,
            };
            let d = derivatives(
                &m,
                &self.wave,
                0.0,
                self.t_end,
                &rest,
                &self.method,
                &held,
                schedule,
                &seeds,
                self.derived_fn,
                &NEVER,
            )
            .unwrap()
            .unwrap();
            assert_eq!(d.readings.len(), base.len() * names.len());
            d.readings
        }

        /// Central differences of the readings with steps `h`, [time][name].
        fn differences(&self, names: &[&str], h: &[f64]) -> Vec<f64> {
            let m = self.model();
            let rest = m.rest_state();
            let names_s: Vec<String> = names.iter().map(|s| s.to_string()).collect();
            let seeds = parse_seeds(&m, &names_s, self.derived_fn).unwrap();
            let n = names.len();
            let mut fd = Vec::new();
            for (j, name) in names.iter().enumerate() {
                let (plus, minus) = match seeds[j] {
                    Seed::State(c) => {
                        let (mut yp, mut ym) = (rest.clone(), rest.clone());
                        yp[c] += h[j];
                        ym[c] -= h[j];
                        (self.readings(&yp).0, self.readings(&ym).0)
                    }
                    _ => {
                        let v = m.params.get(name).or(m.effects.get(name)).unwrap();
                        (
                            self.with(name, v + h[j]).readings(&rest).0,
                            self.with(name, v - h[j]).readings(&rest).0,
                        )
                    }
                };
                if fd.is_empty() {
                    fd = vec![0.0; plus.len() * n];
                }
                for t in 0..plus.len() {
                    fd[t * n + j] = (plus[t] - minus[t]) / (2.0 * h[j]);
                }
            }
            fd
        }

        /// Every name's derivative within `rel` of its central difference, relative to the
        /// largest |derivative| of that name over the run.
        ///
        /// A central difference of a stick-slip run is off in two ways: the run's rounding
        /// noise divided by the step (friction switching amplifies it), and, where a step of
        /// the run straddles a kink of the friction law (v1 = 0 inside a stage), a bias
        /// proportional to the step. So each name is tried at steps h, h/10, h/100 and passes
        /// at the first where the engine agrees within `rel` of the scale plus four times the
        /// differences' own spread (h against 2h). A dropped or wrong term is off by far more.
        fn check(&self, names: &[&str], h: &[f64], rel: f64) {
            let d = self.engine(names);
            let n = names.len();
            let nt = d.len() / n;
            for (j, name) in names.iter().enumerate() {
                let mut verdicts = Vec::new();
                let passed = [1.0, 0.1, 0.01].iter().any(|f| {
                    let fd = self.differences(&[name], &[h[j] * f]);
                    let fd2 = self.differences(&[name], &[2.0 * h[j] * f]);
                    let scale = fd.iter().fold(0.0f64, |a, b| a.max(b.abs()));
                    assert!(scale > 0.0, "{name}: the reading does not depend on it");
                    let noise = fd.iter().zip(&fd2).map(|(a, b)| (a - b).abs()).fold(0.0, f64::max);
                    let worst = (0..nt).map(|t| (d[t * n + j] - fd[t]).abs()).fold(0.0, f64::max);
                    verdicts.push(format!(
                        "h x {f}: {:.2e} of the scale (spread {:.2e})",
                        worst / scale,
                        noise / scale
                    ));
                    noise <= 1e-3 * scale && worst <= rel * scale + 4.0 * noise
                });
                eprintln!("{name}: {}", verdicts.join("; "));
                assert!(
                    passed,
                    "{name}: engine and central differences disagree: {}",
                    verdicts.join("; ")
                );
            }
        }
    }

    /// One pass over `names` on num-dual's 8-wide numbers and on `Tangent<8>`.
    fn both_passes(
        c: &Case,
        names: &[&str],
        y0: &[f64],
    ) -> (Result<PassOutput, SimError>, Result<PassOutput, SimError>) {
        let m = c.model();
        let names_s: Vec<String> = names.iter().map(|s| s.to_string()).collect();
        let seeds = parse_seeds(&m, &names_s, c.derived_fn).unwrap();
        let held = Held::default();
        let dt = c.method.fixed_step().unwrap();
        let pass = Pass {
            model: &m,
            wave: &c.wave,
            t_start: 0.0,
            t_end: c.t_end,
            y0,
            method: &c.method,
            held: &held,
            schedule: Schedule {
                every: c.every,
                also_last: true,
            },
            seeds: &seeds,
            normal_force_derived: c.derived_fn,
        };
        (
            pass.go::<DualSVec64<MAX_PER_PASS>>(&NEVER).unwrap(),
            pass.go_tangent::<MAX_PER_PASS>(dt, &NEVER).unwrap(),
        )
    }

    /// Equal, a -0.0 for a +0.0 allowed (num-dual's "no derivative" is 0 in a tangent).
    fn assert_same(a: &[f64], b: &[f64], what: &str) {
        assert_eq!(a.len(), b.len(), "{what}");
        for (i, (x, y)) in a.iter().zip(b).enumerate() {
            assert!(
                x.to_bits() == y.to_bits() || (*x == 0.0 && *y == 0.0),
                "{what} [{i}]: {x:e} vs {y:e}"
            );
        }
    }

    #[test]
    fn tangent_passes_are_num_duals_bit_for_bit_on_every_kind_of_model() {
        let lags = Effects {
            kappa: 0.05,
            tau_creep: 2e-4,
            tau_sensor: 5e-6,
            c_weight: 30.0,
            drift_rate: 1e-4,
            ..Effects::default()
        };
        let mut cases = vec![
            (
                paper(Structure::Lps, Effects::default()),
                vec![
                    "mu_k",
                    "mu_s",
                    "m2",
                    "fric_alpha",
                    "sigma1",
                    "d33",
                    "hyst_alpha",
                    "stribeck_velocity",
                ],
            ),
            (
                paper(Structure::Dps(3), Effects::default()),
                vec![
                    "m1",
                    "pe_youngs",
                    "pe_density",
                    "rayleigh_alpha",
                    "normal_force",
                    "stribeck_exponent",
                ],
            ),
            (
                paper(Structure::Lps, lags),
                vec![
                    "kappa",
                    "tau_creep",
                    "tau_sensor",
                    "c_weight",
                    "drift_rate",
                    "m1",
                    "fric_n",
                ],
            ),
        ];
        let mut derived = paper(Structure::Lps, Effects::default());
        derived.derived_fn = true;
        derived.hyst = false;
        cases.push((derived, vec!["m1", "m2", "mu_k"]));
        for (c, names) in cases.iter_mut() {
            // coarser steps than the central-difference tests: equality needs no accuracy
            c.method = Method::Rk4 { dt: 5e-8 };
            c.every = 400;
            let rest = c.model().rest_state();
            let (a, b) = both_passes(c, names, &rest);
            let ((ra, fa), (rb, fb)) = (a.unwrap(), b.unwrap());
            assert!(
                ra.iter().any(|x| *x != 0.0),
                "{names:?}: the pass carried no derivative"
            );
            assert_same(&ra, &rb, &format!("readings {names:?}"));
            assert_same(&fa, &fb, &format!("final state {names:?}"));
        }
        // initial-state seeds
        let c = paper(Structure::Lps, Effects::default());
        let mut y0 = c.model().rest_state();
        y0[0] = 1e-7;
        y0[2] = -1e-3;
        let (a, b) = both_passes(&c, &["q0", "v0", "mu_k"], &y0);
        let ((ra, _), (rb, _)) = (a.unwrap(), b.unwrap());
        assert_same(&ra, &rb, "initial-state seeds");
    }

    #[test]
    fn a_tangent_pass_that_blows_up_stops_there_with_the_reason() {
        // a step far beyond the friction state's stability limit while sliding: the run stays
        // bounded, its derivatives do not
        let mut c = paper(Structure::Lps, Effects::default());
        c.hyst = false;
        c.method = Method::Rk4 { dt: 2e-7 };
        c.every = 10;
        c.t_end = 5e-3;
        c.wave = PiecewiseLinear::triangle(100.0, 2e-4, 1e-6, 0.0).unwrap();
        let rest = c.model().rest_state();
        let (a, b) = both_passes(&c, &["mu_k", "m1", "sigma1"], &rest);
        let (ea, eb) = (a.unwrap_err().to_string(), b.unwrap_err().to_string());
        let at = |e: &str| {
            e.split("from t = ")
                .nth(1)
                .map(|x| x.split(' ').next().unwrap().to_string())
        };
        assert!(eb.contains("not finite") && eb.contains("smaller dt"), "{eb}");
        assert_eq!(at(&ea), at(&eb), "the same first time: {ea} | {eb}");
        // a one-name pass (num-dual's scalar dual, the generic driver) stops there too
        let m = c.model();
        let seeds = parse_seeds(&m, &["mu_k".to_string()], false).unwrap();
        let (_, held) = c.readings(&rest);
        let schedule = Schedule {
            every: c.every,
            also_last: true,
        };
        let one = derivatives(
            &m, &c.wave, 0.0, c.t_end, &rest, &c.method, &held, schedule, &seeds, false, &NEVER,
        )
        .unwrap();
        let e1 = one.unwrap_err().to_string();
        assert!(e1.contains("not finite"), "{e1}");
        // a pass cancelled from outside is cancelled, not an error
        let cancelled = AtomicBool::new(true);
        assert!(
            derivatives(&m, &c.wave, 0.0, c.t_end, &rest, &c.method, &held, schedule, &seeds, false, &cancelled)
                .is_none()
        );
    }

    fn rel_step(c: &Case, name: &str) -> f64 {
        1e-6 * c.p.get(name).or(c.e.get(name)).unwrap().abs()
    }

    #[test]
    fn lps_sensitivities_equal_central_differences() {
        let c = paper(Structure::Lps, Effects::default());
        let names = [
            "mu_k",
            "mu_s",
            "m2",
            "fric_alpha",
            "sigma1",
            "sigma2",
            "d33",
            "hyst_alpha",
            "fric_beta",
            "stribeck_velocity",
        ];
        // the reading hardly depends on sigma1 over this run: a larger step keeps its
        // difference above the rounding noise
        let h: Vec<f64> = names
            .iter()
            .map(|n| rel_step(&c, n) * if *n == "sigma1" { 100.0 } else { 1.0 })
            .collect();
        c.check(&names, &h, 1e-6);
    }

    #[test]
    fn exponents_at_their_special_values_are_differentiated_through_the_power() {
        // delta = 2 and n = 1 take shortcuts in the plain run; their derivatives need the power
        let c = paper(Structure::Lps, Effects::default());
        c.check(&["stribeck_exponent", "fric_n"], &[2e-6, 1e-6], 1e-6);
    }

    #[test]
    fn dps_sensitivities_equal_central_differences_including_the_bar() {
        let c = paper(Structure::Dps(4), Effects::default());
        let names = [
            "m1",
            "pe_youngs",
            "pe_density",
            "rayleigh_alpha",
            "rayleigh_beta",
            "normal_force",
            "pe_length",
        ];
        let h: Vec<f64> = names.iter().map(|n| rel_step(&c, n)).collect();
        c.check(&names, &h, 1e-6);
    }

    #[test]
    fn derived_normal_force_follows_the_masses() {
        let mut c = paper(Structure::Lps, Effects::default());
        c.derived_fn = true;
        c.check(&["m1", "m2"], &[1e-7, 1e-7], 1e-6);
        let m = c.model();
        let err = parse_seeds(&m, &["normal_force".into()], true).unwrap_err();
        assert!(err.contains("derived"), "{err}");
    }

    #[test]
    fn initial_state_sensitivities_equal_central_differences() {
        let c = paper(Structure::Lps, Effects::default());
        c.check(&["q0", "v0", "v1"], &[1e-12, 1e-9, 1e-9], 1e-6);
    }

    #[test]
    fn every_effect_parameter_has_its_sensitivity() {
        let e = Effects {
            theta_rad: 0.05,
            k_ground: 2e3,
            tau_amp: 2e-5,
            kappa: 0.05,
            tau_creep: 3e-4,
            c_weight: 1.0,
            eps: 0.05,
            tau_sensor: 1e-5,
            drift_rate: 1e-4,
            // the library at small values (its derivatives are what discovery screens with)
            // each large enough (~1-10 mN along the run) for a central difference to resolve it
            lib_x1: 1e3,
            lib_v1: 0.1,
            lib_dx: 1e3,
            lib_dv: 0.5,
            lib_sgn: 0.01,
            lib_abs: 0.5,
            lib_vv: 200.0,
            lib_volt: 1e-4,
            lib_dvolt: 1e-8,
            lib_t: 0.5,
            lib_x1sq: 1e9,
            lib_x1cube: 1e16,
            lib_sin: 0.01,
            lib_cos: 0.01,
            lib_ff: 0.01,
            lib_ff_sin: 0.02,
            lib_ff_cos: 0.01,
            lib_wavelength: 20e-6,
            libw_x2: 1e4,
            libw_v2: 0.5,
            libw_dx: 1e4,
            libw_dv: 0.5,
            libw_sgn: 0.01,
            libw_vv: 100.0,
            libw_volt: 1e-4,
            libw_dvolt: 1e-8,
        };
        // dt 2e-8: a fifth of the paper case's RK4 stability limit (1e-7 s), and half the CI
        // time of this, the longest unit test (the comparison is within one discretisation)
        let mut c = paper(Structure::Lps, e);
        c.method = Method::Rk4 { dt: 2e-8 };
        let names = EFFECT_NAMES;
        let h: Vec<f64> = names.iter().map(|n| rel_step(&c, n)).collect();
        c.check(&names, &h, 1e-6);
    }

    #[test]
    fn a_rig_has_its_sensitivities() {
        let mut p = Params::paper();
        p.m1 = 0.5;
        p.normal_force = 4.9;
        let c = Case {
            p,
            e: Effects::default(),
            s: Structure::Rig(RigDrive::Position {
                stiffness: 2e4,
                damping: 5.0,
            }),
            hyst: false,
            wave: PiecewiseLinear::new(vec![0.0, 1.0], vec![0.0, 2e-2]).unwrap(),
            t_end: 0.01,
            method: Method::Rk4 { dt: 2e-8 },
            every: 5_000,
            derived_fn: false,
        };
        let names = ["m1", "mu_k", "mu_s", "sigma2", "normal_force"];
        let h: Vec<f64> = names.iter().map(|n| rel_step(&c, n)).collect();
        c.check(&names, &h, 1e-6);
    }

    #[test]
    fn adaptive_runs_are_differentiated_with_their_steps_held() {
        // the derivative of each adaptive run against RK4's (checked against differences
        // above): two discretisations of one derivative, agreeing to their tolerance
        let mut rk4 = paper(Structure::Lps, Effects::default());
        rk4.method = Method::Rk4 { dt: 1e-9 };
        rk4.every = 10_000;
        rk4.t_end = 0.6e-3;
        let names = ["mu_k", "m2", "fric_alpha", "hyst_alpha"];
        let reference = rk4.engine(&names);
        for method in [
            Method::Dopri5 {
                rtol: 1e-9,
                atol: 1e-9,
                first_step: 1e-9,
            },
            Method::Rodas4 {
                rtol: 1e-8,
                atol: 1e-8,
                first_step: 1e-9,
            },
        ] {
            let mut c = rk4.clone();
            c.method = method;
            c.every = 1;
            // the adaptive run saves every step: compare at the end of the run
            let d = c.engine(&names);
            let last = &d[d.len() - names.len()..];
            let r_last = &reference[reference.len() - names.len()..];
            for (j, name) in names.iter().enumerate() {
                let rel = (last[j] - r_last[j]).abs() / r_last[j].abs();
                eprintln!("{method:?} {name}: {rel:.2e} from RK4's");
                assert!(rel < 1e-3, "{method:?} {name}: {} vs RK4 {}", last[j], r_last[j]);
            }
            let m = c.model();
            let (_, held) = c.readings(&m.rest_state());
            assert_eq!(held.steps.len() * m.layout.dim, held.states.len());
        }
    }

    #[test]
    fn more_names_than_one_pass_carries_agree_with_fewer() {
        let c = paper(Structure::Lps, Effects::default());
        let many = [
            "mu_k",
            "mu_s",
            "m1",
            "m2",
            "fric_alpha",
            "sigma1",
            "sigma2",
            "d33",
            "hyst_alpha",
            "q0",
        ];
        let d_many = c.engine(&many);
        let d_one = c.engine(&["hyst_alpha"]);
        let n = many.len();
        for t in 0..d_one.len() {
            assert_eq!(d_many[t * n + 8], d_one[t], "sample {t}");
        }
    }

    #[test]
    fn without_a_stribeck_peak_moving_mu_s_with_mu_k_is_differentiable() {
        // at mu_s = mu_k the readings have a kink in mu_s - mu_k (docs/SENSITIVITIES.md); along
        // mu_s = mu_k they are smooth and the sum of the two derivatives is that direction's
        let mut c = paper(Structure::Lps, Effects::default());
        c.p.mu_s = c.p.mu_k;
        let d = c.engine(&["mu_k", "mu_s"]);
        let shifted = |s: f64| {
            let mut x = c.clone();
            x.p.mu_k += s;
            x.p.mu_s += s;
            x.readings(&x.model().rest_state()).0
        };
        let h = 1e-7;
        let (up, down) = (shifted(h), shifted(-h));
        let fd: Vec<f64> = up.iter().zip(&down).map(|(a, b)| (a - b) / (2.0 * h)).collect();
        let scale = fd.iter().fold(0.0f64, |a, b| a.max(b.abs()));
        let worst = (0..fd.len())
            .map(|t| (d[2 * t] + d[2 * t + 1] - fd[t]).abs())
            .fold(0.0, f64::max);
        eprintln!("tied mu_s = mu_k: {:.2e} of the scale", worst / scale);
        assert!(scale > 0.0 && worst < 1e-5 * scale, "{worst:e} vs scale {scale:e}");
    }

    #[test]
    fn bad_names_are_refused_with_the_reason() {
        let m = paper(Structure::Lps, Effects::default()).model();
        let err = |names: &[&str]| {
            parse_seeds(&m, &names.iter().map(|s| s.to_string()).collect::<Vec<_>>(), false).unwrap_err()
        };
        assert!(err(&["wind"]).contains("unknown sensitivity 'wind'"));
        assert!(err(&["mu_k", "mu_k"]).contains("twice"));
        assert!(err(&["tau_amp"]).contains("off"));
        assert!(err(&["kappa"]).contains("off"));
    }
}
