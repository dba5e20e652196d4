//! Checking a run before any work and explaining a failed one: RK4's step plan (whole steps,
//! breakpoints on the grid, stable for the structure and the lags), a step that fits, and the
//! message of a divergence with a step to try.

use crate::integrate::method::Method;
use crate::integrate::task::{SimError, Task};
use crate::model::Model;
use crate::physics::waveform::PiecewiseLinear;

/// RK4's stability limit on the imaginary axis is 2 sqrt 2; keep a margin.
pub const RK4_STABLE_OMEGA_DT: f64 = 2.5;

/// Number of RK4 steps of `dt` from `t_start` to `t_end`, refusing a `dt` that does not divide
/// them into whole steps or the input's breakpoints, or that the structure's highest mode or a
/// fast effect lag makes unstable. The message names the parameter and a step that works.
pub fn plan_steps(model: &Model, wave: &PiecewiseLinear, t_start: f64, t_end: f64, dt: f64) -> Result<usize, SimError> {
    if !(dt.is_finite() && dt > 0.0) {
        return Err(SimError::Input(format!(
            "parameter 'dt' must be positive and finite, got {dt}"
        )));
    }
    check_span(t_start, t_end)?;
    let whole = |x: f64| (x / dt - (x / dt).round()).abs() <= 1e-6;
    let suggestion = || match fitting_step(wave, t_start, t_end, dt) {
        Some(d) => format!("dt = {d:e} s divides the run and every breakpoint"),
        None => "choose a dt that divides t_start, t_end and every breakpoint time".into(),
    };
    if !whole(t_start) {
        return Err(SimError::Input(format!(
            "t_start = {t_start:e} s is not a whole number of steps dt = {dt:e} s; \
             start on a multiple of dt, or use {}",
            suggestion()
        )));
    }
    // a breakpoint off the step grid is named first: it is usually the cause (a rise time that
    // is not a multiple of dt), even when t_end does not divide either
    if let Some(ti) = wave.misaligned(dt, t_end) {
        return Err(SimError::Input(format!(
            "dt = {dt:e} s does not divide the waveform breakpoint at t = {ti:e} s (where the input \
             changes slope, e.g. the end of a rise; breakpoints must fall on step boundaries); {}",
            suggestion()
        )));
    }
    if let Some(ti) = model.external.as_ref().and_then(|x| x.knots.misaligned(dt, t_end)) {
        return Err(SimError::Input(format!(
            "dt = {dt:e} s does not divide the external force's sample at t = {ti:e} s (its samples \
             must fall on step boundaries with RK4); sample the force on a multiple of dt, or use an \
             adaptive method"
        )));
    }
    let steps = ((t_end - t_start) / dt).round();
    if (steps * dt - (t_end - t_start)).abs() > 1e-6 * dt || steps < 1.0 {
        return Err(SimError::Input(format!(
            "dt = {dt:e} s does not divide t_end = {t_end:e} s into whole steps; {}",
            suggestion()
        )));
    }
    // a first-order lag much faster than the step makes its state stiff: RK4 would diverge
    for (name, tau) in model.effects.lags() {
        if tau > 0.0 && tau * RK4_STABLE_OMEGA_DT < dt {
            return Err(SimError::Input(format!(
                "effect parameter '{name}' = {tau:e} s is too short for dt = {dt:e} s (RK4 needs dt <= {:.3e} s); \
                 use a smaller dt, or 0 to switch the effect off",
                tau * RK4_STABLE_OMEGA_DT
            )));
        }
    }
    let (limit, fastest) = rk4_structure_limit(&model.mech.eigenvalues());
    if dt > limit {
        let works = fitting_step(wave, t_start, t_end, limit)
            .map(|d| format!(" (dt = {d:e} s fits this input)"))
            .unwrap_or_default();
        let mode = if fastest.im.abs() < 1e-9 * fastest.norm() {
            format!(
                "an overdamped mode at {:.4e} 1/s, from the stiffness-proportional damping",
                -fastest.re
            )
        } else {
            format!(
                "{:.4e} rad/s, damping ratio {:.2}",
                fastest.norm(),
                -fastest.re / fastest.norm()
            )
        };
        return Err(SimError::Input(format!(
            "dt = {dt:e} s is unstable for the structure's fastest mode ({mode}); use dt <= {limit:.3e} s{works}, \
             or an adaptive method"
        )));
    }
    Ok(steps as usize)
}

/// The largest RK4 step [s] that keeps every eigenvalue `lambdas` [1/s] of the damped structure
/// inside RK4's region of absolute stability, with the margin RK4_STABLE_OMEGA_DT / 2√2 that the
/// undamped check keeps on the imaginary axis; and the eigenvalue that sets it (∞ and 0 when
/// there is none, as for a rigid body).
pub fn rk4_structure_limit(lambdas: &[nalgebra::Complex<f64>]) -> (f64, nalgebra::Complex<f64>) {
    let margin = RK4_STABLE_OMEGA_DT / (2.0 * std::f64::consts::SQRT_2);
    let mut best = (f64::INFINITY, nalgebra::Complex::new(0.0, 0.0));
    for &l in lambdas {
        let r = l.norm();
        if !(r > 0.0 && r.is_finite()) {
            continue;
        }
        let h = margin * rk4_reach(l / r) / r;
        if h < best.0 {
            best = (h, l);
        }
    }
    best
}

/// How far RK4's region of absolute stability reaches along the ray `dir` (|dir| = 1) from the
/// origin: the first |z| at which |R(z)| = |1 + z + z²/2 + z³/6 + z⁴/24| exceeds 1 (0 for a ray
/// into the right half-plane, where a growing mode is physics, not instability: ∞).
fn rk4_reach(dir: nalgebra::Complex<f64>) -> f64 {
    let grows = |r: f64| {
        let z = dir * r;
        (1.0 + z + z * z / 2.0 + z * z * z / 6.0 + z * z * z * z / 24.0).norm() > 1.0 + 1e-12
    };
    if dir.re > 1e-12 {
        return f64::INFINITY;
    }
    // the region lies within |z| < 3; scan, then bisect the first crossing
    let step = 1e-3;
    let mut r = step;
    while r < 4.0 && !grows(r) {
        r += step;
    }
    let (mut lo, mut hi) = (r - step, r);
    for _ in 0..50 {
        let mid = 0.5 * (lo + hi);
        if grows(mid) {
            hi = mid;
        } else {
            lo = mid;
        }
    }
    lo
}

/// An RK4 step not above `dt` [s] that puts `t_start`, `t_end` and every breakpoint of `wave` in
/// between on the step grid (steps count from t = 0): the largest round one (1, 2, 2.5, 4 or 5
/// times a power of ten) within a factor 10 below `dt`, else the largest t_end / k; `None` if
/// neither is found.
pub fn fitting_step(wave: &PiecewiseLinear, t_start: f64, t_end: f64, dt: f64) -> Option<f64> {
    if !(dt.is_finite() && dt > 0.0 && t_end.is_finite() && t_end > 0.0) {
        return None;
    }
    let fits = |d: f64| {
        let whole = |x: f64| ((x / d) - (x / d).round()).abs() <= 1e-6;
        whole(t_start) && whole(t_end) && wave.misaligned(d, t_end).is_none()
    };
    let decade = dt.log10().floor();
    let round = (0..3)
        .flat_map(|k| [5.0, 4.0, 2.5, 2.0, 1.0].map(|m| m * 10f64.powf(decade - k as f64)))
        .map(|d| format!("{d:.6e}").parse::<f64>().unwrap_or(d)) // exactly the printed value
        .filter(|&d| d <= dt * (1.0 + 1e-12) && d >= dt / 10.0)
        .find(|&d| fits(d));
    if round.is_some() {
        return round;
    }
    let first = (t_end / dt * (1.0 - 1e-12)).ceil().max(1.0);
    if first > 1e13 {
        return None;
    }
    (0..100_000u64).map(|i| t_end / (first + i as f64)).find(|&d| fits(d))
}

/// Refuse a time span that is not finite or not increasing.
pub fn check_span(t_start: f64, t_end: f64) -> Result<(), SimError> {
    if !(t_end.is_finite() && t_end > 0.0) {
        return Err(SimError::Input(format!(
            "parameter 't_end' must be positive and finite, got {t_end}"
        )));
    }
    if !(t_start.is_finite() && t_start >= 0.0 && t_start < t_end) {
        return Err(SimError::Input(format!(
            "parameter 't_start' must be finite, non-negative and before t_end = {t_end:e} s, got {t_start}"
        )));
    }
    Ok(())
}

/// Check a run's settings before any work: the span, and for RK4 the step plan.
pub fn check_task(task: &Task, method: &Method) -> Result<(), SimError> {
    method.validate().map_err(SimError::from)?;
    task.model.check_state(task.y0).map_err(SimError::from)?;
    match *method {
        Method::Rk4 { dt } => plan_steps(task.model, task.wave, task.t_start, task.t_end, dt).map(|_| ()),
        Method::Dopri5 { .. } | Method::Rodas4 { .. } | Method::Auto { .. } => check_span(task.t_start, task.t_end),
    }
}

/// The message of a divergence at time `t` [s] in state `y` with RK4 step `dt` [s], `v_last`
/// [m/s] the main body's velocity at the last state that was still within bounds: where the state
/// left its bounds and a step to try. The step comes from the stability estimate of the friction
/// state at `v_last` (the diverged state's own velocity is meaningless), never below dt / 64,
/// and is fitted to the run's breakpoints and span when `wave` is given.
pub fn divergence_message(
    model: &Model,
    dt: f64,
    t: f64,
    y: &[f64],
    v_last: f64,
    fit: Option<(&PiecewiseLinear, f64, f64)>,
) -> String {
    let l = model.layout;
    let stiff = model.friction.sliding_stiffness(v_last);
    let structure = rk4_structure_limit(&model.mech.eigenvalues()).0;
    let friction = if stiff.is_finite() && stiff > 0.0 {
        RK4_STABLE_OMEGA_DT / stiff
    } else {
        f64::INFINITY
    };
    let stable = if structure.min(friction).is_finite() {
        structure.min(friction)
    } else {
        f64::NAN
    };
    // RK4 failed at dt: the hint is below it, and a blown-up estimate is not trusted below dt/64
    let raw = if stable.is_finite() {
        stable.clamp(dt / 64.0, dt / 2.0)
    } else {
        dt / 4.0
    };
    let hint = fit
        .and_then(|(wave, t0, t1)| fitting_step(wave, t0, t1, raw))
        .unwrap_or(raw);
    format!(
        "integration diverged at t = {t:.6e} s (Fh = {:.4e} N, bound {:.4e} N; v1 = {:.4e} m/s the step \
         before): dt = {dt:e} s is too large for the friction state's stiffness during sliding \
         (stability estimate there: dt <= {stable:.2e} s); try dt = {hint:e} s, or method 'rodas4' \
         (implicit, no such limit)",
        y[l.fh],
        model.presliding_bound(),
        v_last
    )
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::physics::mechanics::{Mechanics, Structure};
    use crate::physics::params::Params;
    use nalgebra::Complex;

    #[test]
    fn rk4_reaches_its_textbook_limits_on_the_axes() {
        // the negative real axis to 2.7853, the imaginary axis to 2√2
        assert!((rk4_reach(Complex::new(-1.0, 0.0)) - 2.785_293_563).abs() < 1e-6);
        assert!((rk4_reach(Complex::new(0.0, 1.0)) - 2.0 * std::f64::consts::SQRT_2).abs() < 1e-3);
        assert!(rk4_reach(Complex::new(1.0, 0.0)).is_infinite());
    }

    #[test]
    fn the_undamped_limit_is_the_old_omega_dt_rule() {
        let w = 1.0e6;
        let (h, _) = rk4_structure_limit(&[Complex::new(0.0, w), Complex::new(0.0, -w)]);
        assert!((h * w / RK4_STABLE_OMEGA_DT - 1.0).abs() < 1e-3, "{}", h * w);
    }

    #[test]
    fn a_fine_bar_is_held_by_its_damped_modes_not_by_its_undamped_frequency() {
        // stiffness-proportional damping moves the fastest modes of a fine bar onto the negative
        // real axis at |λ| ≈ β ω², far beyond ω: the limit is far below 2.5 / ω
        let p = Params::paper();
        let m = Mechanics::new(&p, Structure::Dps(200)).unwrap();
        let (h, fastest) = rk4_structure_limit(&m.eigenvalues());
        let undamped = RK4_STABLE_OMEGA_DT / m.highest_frequency();
        assert!(h < 0.5 * undamped, "limit {h:e} vs undamped {undamped:e}");
        assert!(
            fastest.re < 0.0 && fastest.im.abs() < 1e-6 * fastest.norm(),
            "{fastest}"
        );
        // and a coarse bar is still held by its undamped frequency
        let m = Mechanics::new(&p, Structure::Dps(4)).unwrap();
        let (h, _) = rk4_structure_limit(&m.eigenvalues());
        assert!((h * m.highest_frequency() / RK4_STABLE_OMEGA_DT - 1.0).abs() < 0.05);
    }
}
