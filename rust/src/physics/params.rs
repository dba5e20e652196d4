//! Physical parameters of the IDM (the paper's Table 1), with names as in `MODEL.md`.
//!
//! All values are SI. `Params::paper()` is Table 1; `normal_force` defaults to the weight of the
//! whole device, (m1 + m2 + mPE) g, because the weight and the PE hang on the main body.

use crate::error::InputError;
use crate::numbers::scalar::Scalar;
use crate::physics::declare::{check_domains, same_name, Domain, ParamDecl};

/// Standard gravity used for the default normal force [m/s^2].
pub const GRAVITY: f64 = 9.81;

/// Declares Table 1 once: for each parameter its field, the paper's symbol, unit, meaning,
/// domain and value. From that one list come the fields of [`Params`], [`TABLE1`],
/// [`PARAM_NAMES`], `Params::paper`, `get` and `set`.
macro_rules! table1 {
    ($( $field:ident: $symbol:literal, $unit:literal, $meaning:literal, $domain:expr, $value:expr; )*) => {
        /// IDM parameters (SI units). Field docs give the paper's symbol.
        /// Generic over the number type so the physics can read them as dual numbers
        /// (see [`Params::lift`]); `Params` alone is the plain `f64` table.
        #[derive(Clone, Copy, Debug, PartialEq)]
        pub struct Params<T = f64> {
            $(
                #[doc = concat!($symbol, ", ", $meaning, " [", $unit, "]")]
                pub $field: T,
            )*
        }

        /// Number of parameters in Table 1.
        pub const N_PARAMS: usize = [$(stringify!($field),)*].len();

        /// Table 1, in the order of the fields of [`Params`].
        pub const TABLE1: [ParamDecl; N_PARAMS] = [$(
            ParamDecl {
                name: stringify!($field),
                symbol: $symbol,
                unit: $unit,
                meaning: $meaning,
                domain: $domain,
                value: $value,
            },
        )*];

        /// Every parameter name, in the order of the fields of [`Params`].
        pub const PARAM_NAMES: [&str; N_PARAMS] = [$(stringify!($field),)*];

        impl<S, T: crate::numbers::lane_real::Lanewise<S>> crate::numbers::lane_real::Lanewise<Params<S>> for Params<T> {
            fn splat(src: &Params<S>) -> Self {
                Params { $($field: T::splat(&src.$field),)* }
            }
            fn set_lane(&mut self, i: usize, src: &Params<S>) {
                $(self.$field.set_lane(i, &src.$field);)*
            }
        }

        impl Params {
            /// Every value as a `T` made by `lift(name, value)`: a dual number seeded for the
            /// parameters a derivative is asked for, a constant for the others.
            pub fn lift<T>(&self, lift: impl Fn(&str, f64) -> T) -> Params<T> {
                Params { $($field: lift(stringify!($field), self.$field),)* }
            }

            /// Table 1's values as declared (the normal force still NaN: derived).
            const fn declared() -> Self {
                Params { $($field: $value,)* }
            }

            /// Every value, in the order of [`PARAM_NAMES`].
            pub fn values(&self) -> [f64; N_PARAMS] {
                [$(self.$field,)*]
            }

            fn slot(&mut self, name: &str) -> Option<&mut f64> {
                match name {
                    $(stringify!($field) => Some(&mut self.$field),)*
                    _ => None,
                }
            }
        }
    };
}

table1! {
    m1: "m1", "kg", "main body mass", Domain::Positive, 0.4;
    m2: "m2", "kg", "weight mass", Domain::Positive, 0.3;
    pe_area: "Ap", "m^2", "PE cross-section", Domain::Positive, 2.5e-5;
    pe_youngs: "Ep", "N/m^2", "PE Young's modulus", Domain::Positive, 2.216e10;
    pe_length: "l", "m", "PE length", Domain::Positive, 2e-2;
    // 0 allowed: a massless PE
    pe_density: "rho_p", "kg/m^3", "PE density", Domain::NonNegative, 8000.0;
    d33: "d33", "m/V", "piezoelectric constant", Domain::Positive, 1.24e-7;
    rayleigh_alpha: "alpha_c", "1/s", "mass-proportional Rayleigh damping", Domain::NonNegative, 4e3;
    rayleigh_beta: "beta_c", "s", "stiffness-proportional Rayleigh damping", Domain::NonNegative, 5e-7;
    hyst_alpha: "a_p", "1", "Bouc-Wen piezo hysteresis amplitude", Domain::Finite, 0.4297;
    hyst_beta: "b_p", "1/V", "Bouc-Wen piezo hysteresis shape", Domain::Finite, 3.438e-2;
    hyst_gamma: "c_p", "1/V", "Bouc-Wen piezo hysteresis shape", Domain::Finite, -2.865e-3;
    fric_alpha: "a", "N/m", "presliding stiffness", Domain::Positive, 2e10;
    fric_beta: "b", "1/m", "presliding hysteresis shape", Domain::NonNegative, 0.2e10;
    // may be negative as long as b + c > 0 (see `validate`)
    fric_gamma: "c", "1/m", "presliding hysteresis shape", Domain::Finite, 0.3e10;
    fric_n: "n", "1", "Leuven transition-curve exponent", Domain::Positive, 1.0;
    stribeck_velocity: "v_s", "m/s", "Stribeck velocity", Domain::Positive, 1e-3;
    stribeck_exponent: "delta", "1", "Stribeck exponent", Domain::Positive, 2.0;
    mu_k: "mu_k", "1", "kinetic (Coulomb) friction coefficient", Domain::Positive, 0.5;
    mu_s: "mu_s", "1", "static friction coefficient", Domain::Positive, 0.6;
    sigma1: "sigma1 (r1)", "N s/m", "presliding damping", Domain::NonNegative, 100.0;
    sigma2: "sigma2 (r2)", "N s/m", "viscous friction", Domain::NonNegative, 0.4;
    // not in the paper's Table 1: the operating load of an actuator (0 in the paper)
    load_force: "F_load", "N", "constant external force on the main body along +x (a payload or preload; negative opposes forward motion)", Domain::Finite, 0.0;
    normal_force: "F_n", "N", "normal force on the guide; default (m1+m2+mPE) g", Domain::Positive, f64::NAN;
}

/// The declaration of the Table 1 parameter `name`; a compile error in a `const` when unknown.
pub const fn table1(name: &str) -> ParamDecl {
    let mut i = 0;
    while i < TABLE1.len() {
        if same_name(TABLE1[i].name, name) {
            return TABLE1[i];
        }
        i += 1;
    }
    panic!("not a Table 1 parameter")
}

impl<T: Scalar> Params<T> {
    /// PE mass rho_p Ap l [kg].
    pub fn pe_mass(&self) -> T {
        self.pe_density * self.pe_area * self.pe_length
    }

    /// PE stiffness kp = Ep Ap / l [N/m].
    pub fn kp(&self) -> T {
        self.pe_youngs * self.pe_area / self.pe_length
    }

    /// (m1 + m2 + mPE) g [N]: the whole device rests on the guide through the main body.
    pub fn default_normal_force(&self) -> T {
        (self.m1 + self.m2 + self.pe_mass()) * GRAVITY
    }
}

impl Params {
    /// Table 1 of the paper, with the default normal force.
    pub fn paper() -> Self {
        let mut p = Params::declared();
        p.normal_force = p.default_normal_force();
        p
    }

    /// Upper bound of |Fh| for a run that starts inside it: min(Fs, a/(b+c)) [N].
    pub fn presliding_bound(&self) -> f64 {
        let fs = self.mu_s.max(self.mu_k) * self.normal_force;
        fs.min(self.fric_alpha / (self.fric_beta + self.fric_gamma))
    }

    pub fn get(&self, name: &str) -> Option<f64> {
        self.fields().into_iter().find(|(n, _)| *n == name).map(|(_, v)| v)
    }

    fn fields(&self) -> [(&'static str, f64); N_PARAMS] {
        let v = self.values();
        std::array::from_fn(|i| (PARAM_NAMES[i], v[i]))
    }

    /// Set one parameter by name; unknown names are refused.
    pub fn set(&mut self, name: &str, value: f64) -> Result<(), InputError> {
        let slot = self
            .slot(name)
            .ok_or_else(|| format!("unknown parameter '{name}'; known: {}", PARAM_NAMES.join(", ")))?;
        *slot = value;
        Ok(())
    }

    /// Table 1 overridden by `pairs`; `normal_force` is derived unless given. Validated.
    pub fn from_pairs(pairs: &[(&str, f64)]) -> Result<Self, InputError> {
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

    /// Every value finite and in its declared domain; the error names the parameter.
    pub fn validate(&self) -> Result<(), InputError> {
        check_domains("parameter", &TABLE1, &self.values())?;
        // a relation, not a bound of one value: the presliding force a/(b+c) must be bounded
        if self.fric_beta + self.fric_gamma <= 0.0 {
            return Err(crate::input!(
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
        assert!(Params::from_pairs(&[("mass", 1.0)]).unwrap_err().contains("'mass'"));
        assert!(Params::from_pairs(&[("m1", -1.0)]).unwrap_err().contains("'m1'"));
        assert!(Params::from_pairs(&[("d33", f64::NAN)]).unwrap_err().contains("'d33'"));
    }

    #[test]
    fn normal_force_follows_masses_unless_set() {
        let p = Params::from_pairs(&[("m2", 0.6)]).unwrap();
        assert!((p.normal_force - (1.004 * GRAVITY)).abs() < 1e-12);
        let p = Params::from_pairs(&[("m2", 0.6), ("normal_force", 3.9)]).unwrap();
        assert_eq!(p.normal_force, 3.9);
    }

    #[test]
    fn table1_declares_every_field_once_with_the_paper_values() {
        let p = Params::paper();
        for (i, d) in TABLE1.iter().enumerate() {
            assert_eq!(PARAM_NAMES[i], d.name);
            assert_eq!(TABLE1.iter().filter(|e| e.name == d.name).count(), 1);
            assert!(!d.unit.is_empty() && !d.symbol.is_empty(), "{}", d.name);
            if d.name != "normal_force" {
                assert_eq!(p.get(d.name).unwrap().to_bits(), d.value.to_bits(), "{}", d.name);
            }
        }
        assert!(table1("normal_force").value.is_nan());
        assert_eq!(table1("d33").unit, "m/V");
    }
}
