//! Optional physics beyond the paper's model: the effect catalogue of
//! `recordings/FORMAT.md`. Each is off at its zero value and has one small function here.
//! (`pe_mass` is a change of structure, LPS -> DPS, and `piezo_hysteresis` a switch of the
//! paper's own h state; neither needs a parameter here.)

use crate::params::GRAVITY;

/// Parameter names, as in the catalogue, in field order of [`Effects`].
pub const EFFECT_NAMES: [&str; 9] = [
    "theta_rad",
    "k_ground",
    "tau_amp",
    "kappa",
    "tau_creep",
    "c_weight",
    "eps",
    "tau_sensor",
    "drift_rate",
];

/// Effect parameters (SI). All zero: the paper's model.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Effects {
    /// incline: guide tilt theta [rad]; force -(m1+m2+mPE) g sin(theta) on the main body and
    /// normal force times cos(theta)
    pub theta_rad: f64,
    /// spring_to_ground: force -k_ground x1 on the main body [N/m]
    pub k_ground: f64,
    /// amplifier_lowpass: PE voltage lags the command, dVpe/dt = (Vcmd - Vpe)/tau_amp [s]; 0 = off
    pub tau_amp: f64,
    /// piezo_creep: extra free extension, dxc/dt = (kappa d33 V - xc)/tau_creep [-]
    pub kappa: f64,
    /// piezo_creep time constant [s]; 0 = off
    pub tau_creep: f64,
    /// weight_friction: viscous drag -c_weight v2 on the weight [N s/m]
    pub c_weight: f64,
    /// friction_asymmetry: Fc, Fs times (1 + eps sgn v1) [-]
    pub eps: f64,
    /// sensor_lowpass: the sensor reads x1 through dx/dt = (x1 - x)/tau_sensor [s]; 0 = off
    pub tau_sensor: f64,
    /// thermal_drift: the reading is x1 + drift_rate t [m/s]
    pub drift_rate: f64,
}

impl Effects {
    pub fn set(&mut self, name: &str, value: f64) -> Result<(), String> {
        let slot = match name {
            "theta_rad" => &mut self.theta_rad,
            "k_ground" => &mut self.k_ground,
            "tau_amp" => &mut self.tau_amp,
            "kappa" => &mut self.kappa,
            "tau_creep" => &mut self.tau_creep,
            "c_weight" => &mut self.c_weight,
            "eps" => &mut self.eps,
            "tau_sensor" => &mut self.tau_sensor,
            "drift_rate" => &mut self.drift_rate,
            _ => {
                return Err(format!(
                    "unknown effect parameter '{name}'; known: {}",
                    EFFECT_NAMES.join(", ")
                ))
            }
        };
        *slot = value;
        Ok(())
    }

    pub fn from_pairs(pairs: &[(&str, f64)]) -> Result<Self, String> {
        let mut e = Effects::default();
        for (n, v) in pairs {
            e.set(n, *v)?;
        }
        e.validate()?;
        Ok(e)
    }

    pub fn validate(&self) -> Result<(), String> {
        let all = [
            self.theta_rad,
            self.k_ground,
            self.tau_amp,
            self.kappa,
            self.tau_creep,
            self.c_weight,
            self.eps,
            self.tau_sensor,
            self.drift_rate,
        ];
        for (name, v) in EFFECT_NAMES.iter().zip(all) {
            if !v.is_finite() {
                return Err(format!("effect parameter '{name}' must be finite, got {v}"));
            }
        }
        for (name, v) in [
            ("k_ground", self.k_ground),
            ("tau_amp", self.tau_amp),
            ("tau_creep", self.tau_creep),
            ("c_weight", self.c_weight),
            ("tau_sensor", self.tau_sensor),
        ] {
            if v < 0.0 {
                return Err(format!(
                    "effect parameter '{name}' must be non-negative, got {v}"
                ));
            }
        }
        if self.eps.abs() >= 1.0 {
            return Err(format!(
                "effect parameter 'eps' must lie in (-1, 1), got {}",
                self.eps
            ));
        }
        if self.theta_rad.abs() >= std::f64::consts::FRAC_PI_2 {
            return Err(format!(
                "effect parameter 'theta_rad' must lie in (-pi/2, pi/2), got {}",
                self.theta_rad
            ));
        }
        if self.kappa != 0.0 && self.tau_creep == 0.0 {
            return Err("effect parameter 'kappa' needs a positive 'tau_creep'".into());
        }
        Ok(())
    }

    /// Gravity along the tilted guide on the main body [N], for the device's total mass [kg].
    pub fn incline_force(&self, total_mass: f64) -> f64 {
        -total_mass * GRAVITY * self.theta_rad.sin()
    }

    /// The first-order lags that are on, by parameter name, with their time constants [s]: a
    /// lag much faster than a fixed step makes its state stiff.
    pub fn lags(&self) -> [(&'static str, f64); 3] {
        [
            ("tau_amp", self.tau_amp),
            ("tau_creep", self.tau_creep),
            ("tau_sensor", self.tau_sensor),
        ]
    }

    /// Factor on the normal force from the tilt.
    pub fn normal_scale(&self) -> f64 {
        self.theta_rad.cos()
    }
}

/// Ground spring force on the main body [N].
#[inline(always)]
pub fn ground_spring_force(k_ground: f64, x1: f64) -> f64 {
    -k_ground * x1
}

/// Viscous drag on the weight [N].
#[inline(always)]
pub fn weight_drag(c_weight: f64, v2: f64) -> f64 {
    -c_weight * v2
}

/// First-order lag dy/dt = (u - y)/tau, used by the amplifier, the creep and the sensor.
#[inline(always)]
pub fn first_order_rate(u: f64, y: f64, inv_tau: f64) -> f64 {
    (u - y) * inv_tau
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn incline_pulls_backward_for_positive_tilt() {
        let e = Effects {
            theta_rad: 0.01,
            ..Default::default()
        };
        assert!((e.incline_force(1.0) + GRAVITY * 0.01f64.sin()).abs() < 1e-15);
        assert!(e.normal_scale() < 1.0);
    }

    #[test]
    fn bad_effect_values_are_named() {
        assert!(Effects::from_pairs(&[("tau_amp", -1.0)])
            .unwrap_err()
            .contains("'tau_amp'"));
        assert!(Effects::from_pairs(&[("eps", 1.5)])
            .unwrap_err()
            .contains("'eps'"));
        assert!(Effects::from_pairs(&[("wind", 1.0)])
            .unwrap_err()
            .contains("'wind'"));
    }
}
