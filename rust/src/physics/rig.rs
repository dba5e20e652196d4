//! A friction test rig as a mechanism of the engine: one body (mass `m1`) on the same Leuven
//! friction element as the IDM's main body, driven by the input u(t) — through a spring and
//! damper whose far end follows u as a position [m] (the spring–slider), by u as a force [N] on
//! the body (a force-driven stage), or by a position controller tracking u as the reference
//! [m] (a servo drive such as the EMPS benchmark's: a P position loop inside a P velocity loop,
//! its voltage saturated, times the motor's force constant). No piezo element; the effects that act on the body
//! (incline, spring to ground, friction asymmetry, sensor lag, drift) apply as on the IDM.

use nalgebra::DMatrix;

use crate::error::InputError;
use crate::numbers::real::Real;
use crate::numbers::scalar::Scalar;
use crate::physics::declare::{EffectKind, Part};
use crate::physics::effects::{Effects, EFFECTS};
use crate::physics::params::Params;

/// How the input drives the body.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum RigDrive {
    /// u(t) [m] moves the far end of a spring `stiffness` [N/m] with a damper `damping` [N s/m]
    /// in parallel: force k (u - x) + c (du/dt - v).
    Position { stiffness: f64, damping: f64 },
    /// u(t) [N] is the force on the body.
    Force,
    /// u(t) [m] is a reference position tracked by a cascaded loop: force
    /// `gain sat_limit(kv (kp (u - x) - v))` [N]; `kp` [1/s] the position gain, `kv` [V s/m] the
    /// velocity gain, `gain` [N/V] the actuator constant, `limit` [V] the controller's saturation.
    ClosedLoop { kp: f64, kv: f64, gain: f64, limit: f64 },
}

impl RigDrive {
    /// The drive named `name`, validated: "position" (a spring [N/m] and a damper [N s/m] to the
    /// moving end), "force" (the input is the force), or "closed_loop" (position gain [1/s],
    /// velocity gain [V s/m], actuator constant [N/V], saturation [V]; `limit` 0: none).
    pub fn from_name(
        name: &str,
        stiffness: f64,
        damping: f64,
        kp: f64,
        kv: f64,
        gain: f64,
        limit: f64,
    ) -> Result<Self, InputError> {
        let drive = match name {
            "position" => RigDrive::Position { stiffness, damping },
            "force" => RigDrive::Force,
            // 0: no saturation (the Python stub's literal default)
            "closed_loop" => RigDrive::ClosedLoop {
                kp,
                kv,
                gain,
                limit: if limit == 0.0 { f64::INFINITY } else { limit },
            },
            other => {
                return Err(crate::input!(
                    "parameter 'rig_drive' must be 'position', 'force' or 'closed_loop', got '{other}'"
                ))
            }
        };
        drive.validate()?;
        Ok(drive)
    }

    /// Refuse a spring or damper that is negative or not finite (the message names it).
    // true for NaN as well: a NaN limit is refused like a non-positive one
    #[allow(clippy::neg_cmp_op_on_partial_ord)]
    pub fn validate(&self) -> Result<(), InputError> {
        let non_negative: &[(&str, f64)] = match self {
            RigDrive::Position { stiffness, damping } => &[("rig_stiffness", *stiffness), ("rig_damping", *damping)],
            RigDrive::ClosedLoop { kp, kv, gain, .. } => &[("rig_kp", *kp), ("rig_kv", *kv), ("rig_gain", *gain)],
            RigDrive::Force => &[],
        };
        for &(name, v) in non_negative {
            if !(v.is_finite() && v >= 0.0) {
                return Err(crate::input!(
                    "parameter '{name}' must be finite and non-negative, got {v}"
                ));
            }
        }
        if let RigDrive::ClosedLoop { limit, .. } = *self {
            if !(limit > 0.0) {
                return Err(crate::input!(
                    "parameter 'rig_limit' must be positive (inf for none), got {limit}"
                ));
            }
        }
        Ok(())
    }

    /// Mass, damping and stiffness matrices (1 x 1) of the body on its spring.
    pub fn matrices<T: Scalar>(&self, p: &Params<T>) -> (DMatrix<T>, DMatrix<T>, DMatrix<T>) {
        let (k, c) = match *self {
            RigDrive::Position { stiffness, damping } => (stiffness, damping),
            // the loop's force is not linear (it saturates): it is the drive force
            RigDrive::Force | RigDrive::ClosedLoop { .. } => (0.0, 0.0),
        };
        (
            DMatrix::from_element(1, 1, p.m1),
            DMatrix::from_element(1, 1, T::from(c)),
            DMatrix::from_element(1, 1, T::from(k)),
        )
    }

    /// The drive's force on the body [N] at input `u` rising at `du`, body at `x` [m] moving at
    /// `v` [m/s], beyond the spring's restoring part (which the stiffness matrix carries):
    /// k u + c du/dt for a position drive, u for a force drive, the loop's output for a servo.
    #[inline(always)]
    pub fn drive_force<T: Real>(&self, u: T, du: T, x: T, v: T) -> T {
        match *self {
            RigDrive::Position { stiffness, damping } => u * stiffness + du * damping,
            RigDrive::Force => u,
            RigDrive::ClosedLoop { kp, kv, gain, limit } => {
                let command = ((u - x) * kp - v) * kv;
                // saturated on the value: past the limit the force is constant
                let upper = T::select(command.above(limit), T::from(limit), command);
                let out = T::select(command.below(-limit), T::from(-limit), upper);
                out * gain
            }
        }
    }

    /// (dF/du, dF/dx, dF/dv) of [`RigDrive::drive_force`] at fixed du/dt (the time derivative
    /// along a linear input is dF/du times its slope); 0 where the loop saturates.
    #[inline(always)]
    pub fn drive_partials<T: Scalar>(&self, u: T, x: T, v: T) -> (f64, f64, f64) {
        let (u, x, v) = (u.value(), x.value(), v.value());
        match *self {
            RigDrive::Position { stiffness, .. } => (stiffness, 0.0, 0.0),
            RigDrive::Force => (1.0, 0.0, 0.0),
            RigDrive::ClosedLoop { kp, kv, gain, limit } => {
                if (kv * (kp * (u - x) - v)).abs() < limit {
                    (gain * kv * kp, -gain * kv * kp, -gain * kv)
                } else {
                    (0.0, 0.0, 0.0)
                }
            }
        }
    }

    /// The parts of a device a rig has: one body on the friction element, read by a sensor.
    pub const PARTS: &'static [Part] = &[Part::Main, Part::Reading];

    /// Refuse the piezo switch, and every effect that is on and acts on a part the rig does not
    /// have ([`RigDrive::PARTS`], from each effect's declaration): the message names the first.
    fn refuse_piezo_effects(e: &Effects, piezo_hysteresis: bool) -> Result<(), InputError> {
        if piezo_hysteresis {
            return Err("the rig has no piezo element: use piezo_hysteresis=False".into());
        }
        for decl in EFFECTS.iter().filter(|d| d.kind == EffectKind::Term) {
            let Some(part) = decl.acts_on.iter().find(|p| !Self::PARTS.contains(p)) else {
                continue;
            };
            if let Some(on) = decl.params.iter().find(|q| e.get(q.name).is_some_and(|v| v != 0.0)) {
                return Err(crate::input!(
                    "effect parameter '{}' ({}) acts on the {}, which the rig does not have; set it to 0",
                    on.name,
                    decl.id,
                    part.name()
                ));
            }
        }
        Ok(())
    }
}

impl crate::physics::actuation::Actuation for RigDrive {
    fn check(&self, effects: &Effects, piezo_hysteresis: bool) -> Result<(), InputError> {
        RigDrive::refuse_piezo_effects(effects, piezo_hysteresis)
    }

    /// The rig's one body.
    fn supported_mass<T: Scalar>(&self, p: &Params<T>) -> T {
        p.m1
    }

    /// The drive's force on the body; the rig has no last node of its own.
    #[inline(always)]
    fn forces<T: Real>(&self, _fp: T, u: T, du: T, x: T, v: T) -> (T, T) {
        (self.drive_force(u, du, x, v), T::zero())
    }

    #[inline(always)]
    fn force_partials<T: Scalar>(&self, u: T, x: T, v: T) -> [f64; 5] {
        let (du, dx, dv) = self.drive_partials(u, x, v);
        [0.0, 0.0, du, dx, dv]
    }

    /// The drive's work on the body.
    #[inline(always)]
    fn power<T: Real>(&self, f_main: T, v_main: T, _v_last: T) -> T {
        f_main * v_main
    }

    #[inline(always)]
    fn power_partials<T: Scalar>(&self, f_main: T, v_main: T, _v_last: T) -> [T; 3] {
        [v_main, f_main, T::zero()]
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::integrate::method::Method;
    use crate::model::Model;
    use crate::physics::mechanics::Structure;
    use crate::physics::waveform::PiecewiseLinear;
    use crate::simulate::simulate;

    fn rig_params() -> Params {
        let mut p = Params::paper();
        p.m1 = 0.5;
        p.normal_force = 0.5 * crate::physics::params::GRAVITY;
        p
    }

    /// The rig's physics under Rodas4 at tight tolerances (every step kept): these runs stick or
    /// slide steadily for most of their span, where an implicit step grows far past RK4's
    /// stability limit (2e-8-1e-7 s): 60-5,000 times fewer steps. The values asserted agree
    /// with RK4's well inside their tolerances: breakaway at 1.0149 Fs (RK4 1.0146), sliding
    /// 7.0e-8 off the drive speed (RK4 6.9e-8), the held and the moving body to four digits.
    fn run(drive: RigDrive, wave: &PiecewiseLinear, t_end: f64) -> (Model, crate::simulate::Trajectory) {
        let m = Model::new(rig_params(), Effects::default(), Structure::Rig(drive), false, false).unwrap();
        let method = Method::Rodas4 {
            rtol: 1e-8,
            atol: 1e-8,
            first_step: 1e-6,
        };
        let r = simulate(&m, wave, 0.0, t_end, &m.rest_state(), &method, 1).unwrap();
        (m, r)
    }

    #[test]
    fn spring_slider_sticks_until_the_spring_force_reaches_static_friction() {
        // pulled at 1 mm/s through 2e4 N/m: breakaway when k (V t - x) = Fs
        let (k, speed) = (2e4, 1e-3);
        let drive = RigDrive::Position {
            stiffness: k,
            damping: 0.0,
        };
        let wave = PiecewiseLinear::new(vec![0.0, 1.0], vec![0.0, speed]).unwrap();
        let (m, r) = run(drive, &wave, 0.2);
        let p = rig_params();
        let fs = p.mu_s * p.normal_force;
        // sticking: before breakaway the body moves only by presliding micro-slip, a tiny
        // fraction of the spring's stretch Fs / k
        let slip = r
            .velocities
            .iter()
            .position(|v| v.abs() > 0.1 * p.stribeck_velocity)
            .expect("the body breaks away");
        let t_slip = r.t[slip];
        let x_slip = r.nodes[slip];
        let spring = k * (speed * t_slip - x_slip);
        assert!(x_slip.abs() < 1e-3 * fs / k, "x at breakaway {x_slip}");
        assert!(
            (spring / fs - 1.0).abs() < 0.02,
            "spring force at breakaway {spring} vs Fs {fs}"
        );
        assert!(m.friction_force(&r.final_state).abs() <= m.presliding_bound() * (1.0 + 1e-6));
    }

    #[test]
    fn steady_sliding_friction_is_the_stribeck_curve_at_the_drive_speed() {
        // fast, stiff, damped drive: the body slides steadily at the drive speed
        let speed = 0.02;
        let drive = RigDrive::Position {
            stiffness: 1e5,
            damping: 500.0,
        };
        let wave = PiecewiseLinear::new(vec![0.0, 1.0], vec![0.0, speed]).unwrap();
        let (m, r) = run(drive, &wave, 0.05);
        let y = &r.final_state;
        let v = y[m.layout.dof];
        assert!((v / speed - 1.0).abs() < 1e-6, "v = {v}");
        let p = rig_params();
        let (fc, fs) = (p.mu_k * p.normal_force, p.mu_s * p.normal_force);
        let stribeck = fc + (fs - fc) * (-(speed / p.stribeck_velocity).powf(p.stribeck_exponent)).exp();
        let expected = stribeck + p.sigma2 * speed;
        let ff = m.friction_force(y);
        assert!((ff / expected - 1.0).abs() < 1e-6, "Ff {ff} vs {expected}");
    }

    #[test]
    fn a_force_below_friction_holds_the_body_and_one_above_moves_it() {
        let p = rig_params();
        let hold = |scale: f64| {
            let f = scale * p.mu_s * p.normal_force;
            let wave = PiecewiseLinear::new(vec![0.0, 1e-3], vec![0.0, f]).unwrap();
            let (m, r) = run(RigDrive::Force, &wave, 20e-3);
            (r.final_state[0], r.final_state[m.layout.dof])
        };
        // below Fc: presliding only (nanometres) and at rest
        let (x, v) = hold(0.8);
        assert!(x.abs() < 1e-8 && v.abs() < 1e-6, "x = {x}, v = {v}");
        // above Fs: it accelerates away
        let (x, v) = hold(1.2);
        assert!(x > 1e-5 && v > 1e-3, "x = {x}, v = {v}");
    }

    #[test]
    fn a_servo_tracks_its_reference_with_the_loops_static_error() {
        // a stiff loop holding a position against Coulomb friction: in steady state the loop's
        // force balances the friction, kv kp gain (u - x) = Ff, so the body lags the reference by
        // about Ff / (gain kv kp), the static error of a P-P loop
        let (kp, kv, gain) = (160.0, 240.0, 35.0);
        let drive = RigDrive::ClosedLoop {
            kp,
            kv,
            gain,
            limit: 10.0,
        };
        let wave = PiecewiseLinear::new(vec![0.0, 0.05, 1.0], vec![0.0, 1e-3, 1e-3]).unwrap();
        let m = Model::new(rig_params(), Effects::default(), Structure::Rig(drive), false, false).unwrap();
        let method = Method::Rodas4 {
            rtol: 1e-8,
            atol: 1e-8,
            first_step: 1e-6,
        };
        let r = simulate(&m, &wave, 0.0, 0.3, &m.rest_state(), &method, 1).unwrap();
        let x = r.final_state[0];
        let ff = m.friction_force(&r.final_state);
        // the lag is the static error itself (to 2 %), not merely small
        let static_error = ff / (gain * kv * kp);
        assert!(
            static_error.abs() > 1e-7,
            "a static error worth checking: {static_error}"
        );
        assert!(
            ((1e-3 - x) - static_error).abs() < 0.02 * static_error.abs(),
            "lag {} vs {static_error}",
            1e-3 - x
        );
        let loop_force = gain * kv * kp * (1e-3 - x) - gain * kv * r.final_state[m.layout.dof];
        assert!(
            (loop_force - ff).abs() < 1e-3 * ff.abs().max(1e-3),
            "{loop_force} vs {ff}"
        );
        // and saturates: a far reference drives at most gain * limit
        assert_eq!(drive.drive_force(1.0, 0.0, 0.0, 0.0), gain * 10.0);
        assert!(RigDrive::ClosedLoop {
            kp,
            kv,
            gain,
            limit: 0.0
        }
        .validate()
        .unwrap_err()
        .contains("'rig_limit'"));
    }

    #[test]
    fn structures_and_drives_are_parsed_by_name_and_refused_by_name() {
        let none = || -> Result<RigDrive, InputError> { unreachable!("only a rig builds its drive") };
        assert_eq!(Structure::from_name("lps", 0, none), Ok(Structure::Lps));
        assert_eq!(Structure::from_name("dps", 3, none), Ok(Structure::Dps(3)));
        assert!(Structure::from_name("dps", 0, none)
            .unwrap_err()
            .contains("'n_elements' must be at least 1"));
        assert!(Structure::from_name("fem", 4, none)
            .unwrap_err()
            .contains("'model' must be one of 'lps', 'dps', 'rig', got 'fem'"));
        let rig = |name: &str, limit: f64| RigDrive::from_name(name, 5e4, 2.0, 160.0, 240.0, 35.0, limit);
        assert_eq!(
            rig("position", 0.0),
            Ok(RigDrive::Position {
                stiffness: 5e4,
                damping: 2.0
            })
        );
        assert_eq!(rig("force", 0.0), Ok(RigDrive::Force));
        assert_eq!(
            rig("closed_loop", 0.0),
            Ok(RigDrive::ClosedLoop {
                kp: 160.0,
                kv: 240.0,
                gain: 35.0,
                limit: f64::INFINITY
            })
        );
        assert_eq!(
            rig("closed_loop", 10.0),
            Ok(RigDrive::ClosedLoop {
                kp: 160.0,
                kv: 240.0,
                gain: 35.0,
                limit: 10.0
            })
        );
        assert!(rig("servo", 0.0)
            .unwrap_err()
            .contains("'rig_drive' must be 'position', 'force' or 'closed_loop', got 'servo'"));
        assert!(RigDrive::from_name("position", -1.0, 0.0, 0.0, 0.0, 0.0, 0.0)
            .unwrap_err()
            .contains("'rig_stiffness'"));
        assert_eq!(
            Structure::from_name("rig", 0, || rig("force", 0.0)),
            Ok(Structure::Rig(RigDrive::Force))
        );
    }

    #[test]
    fn rig_refuses_piezo_effects_by_name() {
        let e = Effects {
            c_weight: 1.0,
            ..Default::default()
        };
        let drive = Structure::Rig(RigDrive::Force);
        let err = Model::new(rig_params(), e, drive, false, false).unwrap_err();
        assert!(err.contains("'c_weight'"), "{err}");
        let err = Model::new(rig_params(), Effects::default(), drive, true, false).unwrap_err();
        assert!(err.contains("piezo_hysteresis"), "{err}");
        // every effect parameter, alone: refused exactly when its effect acts on a part the rig
        // lacks (a force on the weight from the library too), run otherwise
        for decl in EFFECTS.iter().filter(|d| d.kind == EffectKind::Term) {
            let lacks = decl.acts_on.iter().any(|p| !RigDrive::PARTS.contains(p));
            for q in decl.params {
                let mut e = Effects::default();
                e.set(q.name, 1e-3).unwrap();
                if q.name == "kappa" {
                    e.tau_creep = 1e-3; // kappa alone is refused for its own reason
                }
                match Model::new(rig_params(), e, drive, false, false) {
                    Err(err) if lacks => assert!(err.contains(&format!("'{}'", q.name)), "{err}"),
                    Ok(_) if !lacks => {}
                    other => panic!("{}: {:?}", q.name, other.map(|_| ())),
                }
            }
        }
    }
}
