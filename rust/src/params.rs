//! Physical parameters of the IDM (the paper's Table 1), with names as in `MODEL.md`.
//!
//! All values are SI. `Params::paper()` is Table 1; `normal_force` defaults to the weight of the
//! whole device, (m1 + m2 + mPE) g, because the weight and the PE hang on the main body.

/// Standard gravity used for the default normal force [m/s^2].
pub const GRAVITY: f64 = 9.81;

/// Every parameter name, in the order of the fields of [`Params`].
pub const PARAM_NAMES: [&str; 23] = [
    "m1",
    "m2",
    "pe_area",
    "pe_youngs",
    "pe_length",
    "pe_density",
    "d33",
    "rayleigh_alpha",
    "rayleigh_beta",
    "hyst_alpha",
    "hyst_beta",
    "hyst_gamma",
    "fric_alpha",
    "fric_beta",
    "fric_gamma",
    "fric_n",
    "stribeck_velocity",
    "stribeck_exponent",
    "mu_k",
    "mu_s",
    "sigma1",
    "sigma2",
    "normal_force",
];

/// IDM parameters (SI units). Field docs give the paper's symbol.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Params {
    /// m1, main body mass [kg]
    pub m1: f64,
    /// m2, weight mass [kg]
    pub m2: f64,
    /// Ap, PE cross-section [m^2]
    pub pe_area: f64,
    /// Ep, PE Young's modulus [N/m^2]
    pub pe_youngs: f64,
    /// l, PE length [m]
    pub pe_length: f64,
    /// rho_p, PE density [kg/m^3] (0 allowed: a massless PE)
    pub pe_density: f64,
    /// d33, piezoelectric constant [m/V]
    pub d33: f64,
    /// alpha_c, mass-proportional Rayleigh damping [1/s]
    pub rayleigh_alpha: f64,
    /// beta_c, stiffness-proportional Rayleigh damping [s]
    pub rayleigh_beta: f64,
    /// a_p, Bouc-Wen piezo hysteresis [-]
    pub hyst_alpha: f64,
    /// b_p, Bouc-Wen piezo hysteresis [1/V]
    pub hyst_beta: f64,
    /// c_p, Bouc-Wen piezo hysteresis [1/V]
    pub hyst_gamma: f64,
    /// a, presliding stiffness [N/m]
    pub fric_alpha: f64,
    /// b, presliding hysteresis shape [1/m]
    pub fric_beta: f64,
    /// c, presliding hysteresis shape [1/m]
    pub fric_gamma: f64,
    /// n, Leuven transition exponent [-]
    pub fric_n: f64,
    /// v_s, Stribeck velocity [m/s]
    pub stribeck_velocity: f64,
    /// delta, Stribeck exponent [-]
    pub stribeck_exponent: f64,
    /// mu_k, kinetic friction coefficient [-]
    pub mu_k: f64,
    /// mu_s, static friction coefficient [-]
    pub mu_s: f64,
    /// sigma1 ("r1"), presliding damping [N s/m]
    pub sigma1: f64,
    /// sigma2 ("r2"), viscous friction [N s/m]
    pub sigma2: f64,
    /// F_n, normal force on the guide [N]
    pub normal_force: f64,
}

impl Params {
    /// Table 1 of the paper, with the default normal force.
    pub fn paper() -> Self {
        let mut p = Params {
            m1: 0.4,
            m2: 0.3,
            pe_area: 2.5e-5,
            pe_youngs: 2.216e10,
            pe_length: 2e-2,
            pe_density: 8000.0,
            d33: 1.24e-7,
            rayleigh_alpha: 4e3,
            rayleigh_beta: 5e-7,
            hyst_alpha: 0.4297,
            hyst_beta: 3.438e-2,
            hyst_gamma: -2.865e-3,
            fric_alpha: 2e10,
            fric_beta: 0.2e10,
            fric_gamma: 0.3e10,
            fric_n: 1.0,
            stribeck_velocity: 1e-3,
            stribeck_exponent: 2.0,
            mu_k: 0.5,
            mu_s: 0.6,
            sigma1: 100.0,
            sigma2: 0.4,
            normal_force: 0.0,
        };
        p.normal_force = p.default_normal_force();
        p
    }

    /// PE mass rho_p Ap l [kg].
    pub fn pe_mass(&self) -> f64 {
        self.pe_density * self.pe_area * self.pe_length
    }

    /// PE stiffness kp = Ep Ap / l [N/m].
    pub fn kp(&self) -> f64 {
        self.pe_youngs * self.pe_area / self.pe_length
    }

    /// (m1 + m2 + mPE) g [N]: the whole device rests on the guide through the main body.
    pub fn default_normal_force(&self) -> f64 {
        (self.m1 + self.m2 + self.pe_mass()) * GRAVITY
    }

    /// Upper bound of |Fh| for a run that starts inside it: min(Fs, a/(b+c)) [N].
    pub fn presliding_bound(&self) -> f64 {
        let fs = self.mu_s.max(self.mu_k) * self.normal_force;
        fs.min(self.fric_alpha / (self.fric_beta + self.fric_gamma))
    }

    pub fn get(&self, name: &str) -> Option<f64> {
        self.fields()
            .into_iter()
            .find(|(n, _)| *n == name)
            .map(|(_, v)| v)
    }

    fn fields(&self) -> [(&'static str, f64); 23] {
        let v = [
            self.m1,
            self.m2,
            self.pe_area,
            self.pe_youngs,
            self.pe_length,
            self.pe_density,
            self.d33,
            self.rayleigh_alpha,
            self.rayleigh_beta,
            self.hyst_alpha,
            self.hyst_beta,
            self.hyst_gamma,
            self.fric_alpha,
            self.fric_beta,
            self.fric_gamma,
            self.fric_n,
            self.stribeck_velocity,
            self.stribeck_exponent,
            self.mu_k,
            self.mu_s,
            self.sigma1,
            self.sigma2,
            self.normal_force,
        ];
        std::array::from_fn(|i| (PARAM_NAMES[i], v[i]))
    }

    /// Set one parameter by name; unknown names are refused.
    pub fn set(&mut self, name: &str, value: f64) -> Result<(), String> {
        let slot = match name {
            "m1" => &mut self.m1,
            "m2" => &mut self.m2,
            "pe_area" => &mut self.pe_area,
            "pe_youngs" => &mut self.pe_youngs,
            "pe_length" => &mut self.pe_length,
            "pe_density" => &mut self.pe_density,
            "d33" => &mut self.d33,
            "rayleigh_alpha" => &mut self.rayleigh_alpha,
            "rayleigh_beta" => &mut self.rayleigh_beta,
            "hyst_alpha" => &mut self.hyst_alpha,
            "hyst_beta" => &mut self.hyst_beta,
            "hyst_gamma" => &mut self.hyst_gamma,
            "fric_alpha" => &mut self.fric_alpha,
            "fric_beta" => &mut self.fric_beta,
            "fric_gamma" => &mut self.fric_gamma,
            "fric_n" => &mut self.fric_n,
            "stribeck_velocity" => &mut self.stribeck_velocity,
            "stribeck_exponent" => &mut self.stribeck_exponent,
            "mu_k" => &mut self.mu_k,
            "mu_s" => &mut self.mu_s,
            "sigma1" => &mut self.sigma1,
            "sigma2" => &mut self.sigma2,
            "normal_force" => &mut self.normal_force,
            _ => {
                return Err(format!(
                    "unknown parameter '{name}'; known: {}",
                    PARAM_NAMES.join(", ")
                ))
            }
        };
        *slot = value;
        Ok(())
    }

    /// Table 1 overridden by `pairs`; `normal_force` is derived unless given. Validated.
    pub fn from_pairs(pairs: &[(&str, f64)]) -> Result<Self, String> {
        let mut p = Params::paper();
        let mut explicit_fn = false;
        for (name, value) in pairs {
            p.set(name, *value)?;
            explicit_fn |= *name == "normal_force";
        }
        if !explicit_fn {
            p.normal_force = p.default_normal_force();
        }
        p.validate()?;
        Ok(p)
    }

    /// Every value finite; physical sizes positive. The error names the parameter.
    pub fn validate(&self) -> Result<(), String> {
        for (name, v) in self.fields() {
            if !v.is_finite() {
                return Err(format!("parameter '{name}' must be finite, got {v}"));
            }
        }
        let positive = [
            ("m1", self.m1),
            ("m2", self.m2),
            ("pe_area", self.pe_area),
            ("pe_youngs", self.pe_youngs),
            ("pe_length", self.pe_length),
            ("d33", self.d33),
            ("fric_alpha", self.fric_alpha),
            ("fric_n", self.fric_n),
            ("stribeck_velocity", self.stribeck_velocity),
            ("stribeck_exponent", self.stribeck_exponent),
            ("mu_k", self.mu_k),
            ("mu_s", self.mu_s),
            ("normal_force", self.normal_force),
        ];
        for (name, v) in positive {
            if v <= 0.0 {
                return Err(format!("parameter '{name}' must be positive, got {v}"));
            }
        }
        let non_negative = [
            ("pe_density", self.pe_density),
            ("rayleigh_alpha", self.rayleigh_alpha),
            ("rayleigh_beta", self.rayleigh_beta),
            ("fric_beta", self.fric_beta),
            ("sigma1", self.sigma1),
            ("sigma2", self.sigma2),
        ];
        for (name, v) in non_negative {
            if v < 0.0 {
                return Err(format!("parameter '{name}' must be non-negative, got {v}"));
            }
        }
        if self.fric_beta + self.fric_gamma <= 0.0 {
            return Err(format!(
                "parameters 'fric_beta' + 'fric_gamma' must be positive (bounded presliding force), got {}",
                self.fric_beta + self.fric_gamma
            ));
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn table1_derived_values_match_model_md() {
        let p = Params::paper();
        assert!((p.kp() - 2.77e7).abs() < 1.0);
        assert!((p.pe_mass() - 4e-3).abs() < 1e-15);
        assert!((p.normal_force - 6.90624).abs() < 1e-12);
        assert!((p.presliding_bound() - 4.0).abs() < 1e-12);
    }

    #[test]
    fn unknown_and_bad_values_are_named() {
        assert!(Params::from_pairs(&[("mass", 1.0)])
            .unwrap_err()
            .contains("'mass'"));
        assert!(Params::from_pairs(&[("m1", -1.0)])
            .unwrap_err()
            .contains("'m1'"));
        assert!(Params::from_pairs(&[("d33", f64::NAN)])
            .unwrap_err()
            .contains("'d33'"));
    }

    #[test]
    fn normal_force_follows_masses_unless_set() {
        let p = Params::from_pairs(&[("m2", 0.6)]).unwrap();
        assert!((p.normal_force - (1.004 * GRAVITY)).abs() < 1e-12);
        let p = Params::from_pairs(&[("m2", 0.6), ("normal_force", 3.9)]).unwrap();
        assert_eq!(p.normal_force, 3.9);
    }
}
