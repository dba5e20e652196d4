//! The simulation driver: steps the model with RK4 under a piecewise-linear input, checks for
//! divergence every step, and hands each state to an observer (saving, metrics).

use crate::model::{with_state_size, Model};
use crate::rk4::{Rhs, Rk4};
use crate::waveform::PiecewiseLinear;

/// RK4's stability limit on the imaginary axis is 2 sqrt 2; keep a margin.
const RK4_STABLE_OMEGA_DT: f64 = 2.5;

/// Why a run stopped without a result.
#[derive(Clone, Debug, PartialEq)]
pub enum SimError {
    /// Bad input (parameters, step size, waveform); the message names what is wrong.
    Input(String),
    /// The state left its physical bounds or became non-finite at time `t` [s].
    Diverged { t: f64, message: String },
}

impl std::fmt::Display for SimError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            SimError::Input(m) => write!(f, "{m}"),
            SimError::Diverged { message, .. } => write!(f, "{message}"),
        }
    }
}

/// Number of steps of size `dt` in `t_end`, refusing a `dt` that does not divide it or that the
/// structure's highest mode makes unstable.
pub fn plan_steps(
    model: &Model,
    wave: &PiecewiseLinear,
    t_end: f64,
    dt: f64,
) -> Result<usize, SimError> {
    if !(dt.is_finite() && dt > 0.0) {
        return Err(SimError::Input(format!(
            "parameter 'dt' must be positive and finite, got {dt}"
        )));
    }
    if !(t_end.is_finite() && t_end > 0.0) {
        return Err(SimError::Input(format!(
            "parameter 't_end' must be positive and finite, got {t_end}"
        )));
    }
    let steps = (t_end / dt).round();
    if (steps * dt - t_end).abs() > 1e-6 * dt || steps < 1.0 {
        return Err(SimError::Input(format!(
            "dt = {dt:e} s does not divide t_end = {t_end:e} s into whole steps"
        )));
    }
    wave.check_alignment(dt, t_end).map_err(SimError::Input)?;
    // a first-order lag much faster than the step makes its state stiff: RK4 would diverge
    let e = &model.effects;
    for (name, tau) in [
        ("tau_amp", e.tau_amp),
        ("tau_creep", e.tau_creep),
        ("tau_sensor", e.tau_sensor),
    ] {
        if tau > 0.0 && tau * RK4_STABLE_OMEGA_DT < dt {
            return Err(SimError::Input(format!(
                "effect parameter '{name}' = {tau:e} s is too short for dt = {dt:e} s (RK4 needs dt <= {:.3e} s); \
                 use a smaller dt, or 0 to switch the effect off",
                tau * RK4_STABLE_OMEGA_DT
            )));
        }
    }
    let w = model.mech.highest_frequency();
    if w * dt > RK4_STABLE_OMEGA_DT {
        return Err(SimError::Input(format!(
            "dt = {dt:e} s is unstable for the highest structural mode ({w:.4e} rad/s); \
             use dt <= {:.3e} s",
            RK4_STABLE_OMEGA_DT / w
        )));
    }
    Ok(steps as usize)
}

/// Initial state: at rest, everything zero (MODEL.md, FORMAT.md).
pub fn rest_state(model: &Model) -> Vec<f64> {
    vec![0.0; model.layout.dim]
}

/// The model under a linear input over one step, per lane: V = v0 + slope c dt. Keeps
/// (Ff, dg/dt) of each lane's first stage, i.e. at the state at the start of the step.
pub struct ModelRhs<'a, const N: usize, const EXTRAS: bool, const L: usize = 1> {
    pub model: &'a Model,
    pub v0: [f64; L],
    pub slope: [f64; L],
    pub dt: f64,
    pub ff_gdot: [(f64, f64); L],
}

impl<const N: usize, const EXTRAS: bool, const L: usize> Rhs for ModelRhs<'_, N, EXTRAS, L> {
    #[inline(always)]
    fn eval(&mut self, lane: usize, c: f64, y: &[f64], dy: &mut [f64]) {
        let out = self.model.rhs_impl::<N, EXTRAS>(
            self.v0[lane] + self.slope[lane] * c * self.dt,
            self.slope[lane],
            y,
            dy,
        );
        if c == 0.0 {
            self.ff_gdot[lane] = out;
        }
    }
}

/// Integrate `steps` steps of `dt` from `y` (at t = 0). After every step the observer gets
/// (step index k >= 1, t, state, commanded voltage). Stops with `Diverged` as soon as the
/// state is non-finite or |Fh| leaves its bound.
pub fn integrate<O: FnMut(usize, f64, &[f64], f64)>(
    model: &Model,
    wave: &PiecewiseLinear,
    dt: f64,
    steps: usize,
    y: &mut [f64],
    observe: O,
) -> Result<(), SimError> {
    // Plain states of the common sizes run on stack arrays (see rk4.rs); same arithmetic.
    macro_rules! fixed {
        ($n:literal, $d:literal) => {{
            let mut a = [0.0; $d];
            a.copy_from_slice(y);
            let r = integrate_with::<_, _, $n, false>(model, wave, dt, steps, &mut a, observe);
            y.copy_from_slice(&a);
            r
        }};
    }
    with_state_size!(model.is_plain(), model.layout.dof, fixed, {
        let mut v = y.to_vec();
        let r = integrate_with::<_, _, 0, true>(model, wave, dt, steps, &mut v, observe);
        y.copy_from_slice(&v);
        r
    })
}

#[inline(always)]
fn integrate_with<S, O, const N: usize, const EXTRAS: bool>(
    model: &Model,
    wave: &PiecewiseLinear,
    dt: f64,
    steps: usize,
    y: &mut S,
    mut observe: O,
) -> Result<(), SimError>
where
    S: AsRef<[f64]> + AsMut<[f64]> + Clone,
    O: FnMut(usize, f64, &[f64], f64),
{
    let mut zero = y.clone();
    zero.as_mut().fill(0.0);
    let mut rk = Rk4::new(zero);
    let l = model.layout;
    // a hair above the bound: RK4 may overshoot it by its truncation error
    let bound = model.presliding_bound() * (1.0 + 1e-6) + 1e-12;
    let (bt, bv) = (wave.times(), wave.values());
    let mut seg = 0usize;
    for k in 0..steps {
        let t0 = k as f64 * dt;
        let t_mid = t0 + 0.5 * dt;
        while seg + 1 < bt.len() && bt[seg + 1] <= t_mid {
            seg += 1;
        }
        // breakpoints sit on step boundaries, so the slope is constant over the whole step
        let (v0, slope) = if t_mid < bt[0] || seg + 1 >= bt.len() {
            (bv[seg], 0.0)
        } else {
            let s = (bv[seg + 1] - bv[seg]) / (bt[seg + 1] - bt[seg]);
            (bv[seg] + s * (t0 - bt[seg]), s)
        };
        let mut f = ModelRhs::<N, EXTRAS> {
            model,
            v0: [v0],
            slope: [slope],
            dt,
            ff_gdot: [(0.0, 0.0)],
        };
        rk.step(&mut f, dt, y);
        let t1 = (k + 1) as f64 * dt;
        let ys = y.as_ref();
        let fh = ys[l.fh];
        if !(fh.abs() <= bound) || !ys[l.dof].is_finite() || !ys[0].is_finite() {
            return Err(diverged(model, dt, t1, ys));
        }
        observe(k + 1, t1, ys, v0 + slope * dt);
    }
    if let Some(i) = y.as_ref().iter().position(|x| !x.is_finite()) {
        return Err(SimError::Diverged {
            t: steps as f64 * dt,
            message: format!("state component {i} is not finite at the end of the run"),
        });
    }
    Ok(())
}

fn diverged(model: &Model, dt: f64, t: f64, y: &[f64]) -> SimError {
    let l = model.layout;
    let v = y[l.dof];
    let stiff = if v.is_finite() {
        model.friction.sliding_stiffness(v)
    } else {
        f64::NAN
    };
    let hint = if stiff.is_finite() && stiff > 0.0 {
        (RK4_STABLE_OMEGA_DT / stiff).min(dt / 2.0)
    } else {
        dt / 4.0
    };
    SimError::Diverged {
        t,
        message: format!(
            "integration diverged at t = {t:.6e} s (Fh = {:.4e} N, bound {:.4e} N; v1 = {:.4e} m/s): \
             dt = {dt:e} s is too large for the friction state's stiffness during sliding; \
             try dt <= {hint:.2e} s",
            y[l.fh],
            model.presliding_bound(),
            v
        ),
    }
}

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
            self.accounting
                .extend_from_slice(&y[a..a + crate::model::N_ACCOUNTING]);
            self.kinetic.push(model.mech.kinetic(&y[n..2 * n]));
            self.strain.push(model.mech.strain(&y[..n]));
            self.momentum.push(model.mech.momentum(&y[n..2 * n]));
        }
    }
}

/// Run from rest to `t_end` with step `dt`, saving every `save_every` steps (and the last).
pub fn simulate(
    model: &Model,
    wave: &PiecewiseLinear,
    t_end: f64,
    dt: f64,
    save_every: usize,
) -> Result<Trajectory, SimError> {
    if save_every == 0 {
        return Err(SimError::Input(
            "parameter 'save_every' must be at least 1".into(),
        ));
    }
    let steps = plan_steps(model, wave, t_end, dt)?;
    let mut y = rest_state(model);
    let mut out = Trajectory {
        dof: model.layout.dof,
        ..Default::default()
    };
    out.record(model, 0.0, &y, wave.value(0.0));
    let mut until_save = save_every;
    integrate(model, wave, dt, steps, &mut y, |k, t, s, v| {
        until_save -= 1; // a countdown, not k % save_every: no division in the step loop
        if until_save == 0 || k == steps {
            out.record(model, t, s, v);
            until_save = save_every;
        }
    })?;
    out.final_state = y;
    Ok(out)
}
