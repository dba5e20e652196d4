//! Optional physics beyond the paper's model: the effect catalogue (docs/RECORDINGS.md),
//! declared once in [`EFFECTS`]. Effects that add a term to the engine are off at their zero
//! value and have one small function here; their parameters are the fields of [`Effects`].
//! (`pe_mass` is a change of structure, LPS -> DPS, and `piezo_hysteresis` and `stribeck`
//! switch on parts of the paper's own model; they are declared here too so the catalogue has
//! one source, but need no field.)

use crate::error::InputError;
use crate::numbers::real::Real;
use crate::numbers::scalar::Scalar;
use crate::physics::declare::{check_domains, Domain, EffectDecl, EffectKind, ParamDecl, Part};
use crate::physics::params::{table1, GRAVITY};

/// Declares the catalogue once. `other` effects change the structure or Table 1 values and
/// list their parameters as [`ParamDecl`]s; each parameter of a `terms` effect becomes a field
/// of [`Effects`] (off at 0). From that one list come the struct, [`EFFECTS`],
/// [`EFFECT_PARAMS`], [`EFFECT_NAMES`], `get` and `set`.
macro_rules! effects {
    (
        other {
            $( $oid:ident ($okind:ident) {
                physics: $ophysics:literal,
                term: $oterm:literal,
                acts_on: [$($opart:ident),+],
                params: [$($oparam:expr),* $(,)?] $(,)?
            } )*
        }
        terms {
            $( $tid:ident {
                physics: $tphysics:literal,
                term: $tterm:literal,
                acts_on: [$($tpart:ident),+],
                $( state: { name: $sname:literal, unit: $sunit:literal, tau: $stau:ident, follows: $sfollows:ident, scale: $sscale:ident }, )?
                params: { $( $field:ident: $symbol:literal, $unit:literal, $domain:expr, $meaning:literal; )* } $(,)?
            } )*
        }
    ) => {
        /// Effect parameters (SI). All zero: the paper's model. Generic over the number type
        /// like [`crate::physics::params::Params`] (see [`Effects::lift`]).
        #[derive(Clone, Copy, Debug, Default, PartialEq)]
        pub struct Effects<T = f64> {
            $($(
                #[doc = concat!(stringify!($tid), ": ", $meaning, " [", $unit, "]")]
                pub $field: T,
            )*)*
        }

        /// Number of effect parameters (fields of [`Effects`]).
        pub const N_EFFECT_PARAMS: usize = [$($(stringify!($field),)*)*].len();

        /// The parameters of the `terms` effects, in field order of [`Effects`].
        pub const EFFECT_PARAMS: [ParamDecl; N_EFFECT_PARAMS] = [$($(
            effects!(@param $field, $symbol, $unit, $domain, $meaning),
        )*)*];

        /// Parameter names, as in the catalogue, in field order of [`Effects`].
        pub const EFFECT_NAMES: [&str; N_EFFECT_PARAMS] = [$($(stringify!($field),)*)*];

        /// The catalogue, in the order the diagnosis tries it.
        pub const EFFECTS: &[EffectDecl] = &[
            $(EffectDecl {
                id: stringify!($oid),
                kind: EffectKind::$okind,
                physics: $ophysics,
                term: $oterm,
                acts_on: &[$(Part::$opart),+],
                params: &[$($oparam),*],
            },)*
            $(EffectDecl {
                id: stringify!($tid),
                kind: EffectKind::Term,
                physics: $tphysics,
                term: $tterm,
                acts_on: &[$(Part::$tpart),+],
                params: &[$(effects!(@param $field, $symbol, $unit, $domain, $meaning)),*],
            },)*
        ];

        /// The effects with a state of their own (first-order lags), in catalogue order, which is
        /// the order of their states in the layout (`model::Layout`).
        pub const LAGS: &[LagDecl] = &[$($(
            LagDecl {
                effect: stringify!($tid),
                state: $sname,
                unit: $sunit,
                tau: stringify!($stau),
                follows: LagInput::$sfollows,
                scale: LagScale::$sscale,
            },
        )?)*];

        impl<T: Copy> Effects<T> {
            /// One parameter by name; None when unknown.
            pub fn value_of(&self, name: &str) -> Option<T> {
                match name {
                    $($(stringify!($field) => Some(self.$field),)*)*
                    _ => None,
                }
            }
        }

        impl<S, T: crate::numbers::lane_real::Lanewise<S>> crate::numbers::lane_real::Lanewise<Effects<S>> for Effects<T> {
            fn splat(src: &Effects<S>) -> Self {
                Effects { $($($field: T::splat(&src.$field),)*)* }
            }
            fn set_lane(&mut self, i: usize, src: &Effects<S>) {
                $($(self.$field.set_lane(i, &src.$field);)*)*
            }
        }

        impl Effects {
            /// Every value as a `T` made by `lift(name, value)` (see `Params::lift`).
            pub fn lift<T>(&self, lift: impl Fn(&str, f64) -> T) -> Effects<T> {
                Effects { $($($field: lift(stringify!($field), self.$field),)*)* }
            }

            /// Every value, in the order of [`EFFECT_NAMES`].
            pub fn values(&self) -> [f64; N_EFFECT_PARAMS] {
                [$($(self.$field,)*)*]
            }

            fn slot(&mut self, name: &str) -> Option<&mut f64> {
                match name {
                    $($(stringify!($field) => Some(&mut self.$field),)*)*
                    _ => None,
                }
            }
        }
    };
    (@param $field:ident, $symbol:literal, $unit:literal, $domain:expr, $meaning:literal) => {
        ParamDecl {
            name: stringify!($field),
            symbol: $symbol,
            unit: $unit,
            meaning: $meaning,
            domain: $domain,
            value: 0.0,
        }
    };
}

effects! {
    other {
        pe_mass (Structure) {
            physics: "the PE has mass: the device is the DPS (4 elements, consistent mass, Rayleigh damping), not the LPS",
            term: "PE as a 4-element bar with mass and Rayleigh damping (DPS)",
            acts_on: [Piezo],
            params: [],
        }
        piezo_hysteresis (Parameter) {
            physics: "the PE force has Bouc-Wen hysteresis h (amplitude hyst_alpha; hyst_beta, hyst_gamma as nominal)",
            term: "Fp = kp (d33 V - h), h' = hyst_alpha d33 V' - hyst_beta |V'| h - hyst_gamma V' |h|",
            acts_on: [Piezo],
            // with h switched on; at hyst_alpha = 0 h stays 0
            params: [ParamDecl { value: 0.0, ..table1("hyst_alpha") }],
        }
        stribeck (Parameter) {
            physics: "static friction exceeds kinetic friction (mu_s > mu_k: a Stribeck peak)",
            term: "s(v) = Fc + (Fs - Fc) exp(-(|v|/vs)^delta), Fs = mu_s Fn > Fc",
            acts_on: [Main],
            // fitted as the excess, so mu_s >= mu_k holds whatever mu_k the fit is at
            params: [ParamDecl {
                name: "mu_s_excess",
                symbol: "mu_s/mu_k - 1",
                unit: "1",
                meaning: "static friction excess, mu_s = mu_k (1 + mu_s_excess)",
                domain: Domain::NonNegative,
                value: 0.0,
            }],
        }
    }
    terms {
        incline {
            physics: "the guide is tilted: gravity along it on the device, normal force times cos(theta)",
            term: "m1 x1'' += -(m1 + m2 + mPE) g sin(theta_rad), Fn *= cos(theta_rad)",
            acts_on: [Main],
            params: {
                theta_rad: "theta", "rad",
                    Domain::Open { lower: -std::f64::consts::FRAC_PI_2, upper: std::f64::consts::FRAC_PI_2, text: "(-pi/2, pi/2)" },
                    "guide tilt; force -(m1+m2+mPE) g sin(theta) on the main body, normal force times cos(theta)";
            },
        }
        spring_to_ground {
            physics: "a spring from the main body to the ground, force -k_ground x1",
            term: "m1 x1'' += -k_ground x1",
            acts_on: [Main],
            params: {
                k_ground: "k_ground", "N/m", Domain::NonNegative, "stiffness of a spring from the main body to ground";
            },
        }
        amplifier_lowpass {
            physics: "the PE voltage lags the command through a first-order amplifier (tau_amp)",
            term: "Vpe' = (Vcmd - Vpe) / tau_amp",
            acts_on: [Piezo],
            state: { name: "v_pe", unit: "V", tau: tau_amp, follows: Command, scale: Voltage },
            params: {
                tau_amp: "tau_amp", "s", Domain::NonNegative, "amplifier lag of the PE voltage behind the command; 0 = off";
            },
        }
        piezo_creep {
            physics: "the PE creeps: an extra free extension relaxing to kappa d33 V with time constant tau_creep",
            term: "xc' = (kappa d33 V - xc) / tau_creep, Fp = kp (d33 V + xc)",
            acts_on: [Piezo],
            state: { name: "x_creep", unit: "m", tau: tau_creep, follows: CreepTarget, scale: Stroke },
            params: {
                kappa: "kappa", "1", Domain::Finite, "creep amplitude, relative to the free extension d33 V";
                tau_creep: "tau_creep", "s", Domain::NonNegative, "creep time constant; 0 = off";
            },
        }
        weight_friction {
            physics: "viscous drag on the weight, force -c_weight v2",
            term: "m2 x2'' += -c_weight x2'",
            acts_on: [Weight],
            params: {
                c_weight: "c_weight", "N s/m", Domain::NonNegative, "viscous drag coefficient on the weight";
            },
        }
        friction_asymmetry {
            physics: "friction levels depend on the sliding direction: Fc, Fs times (1 + eps sgn v1)",
            term: "Fc, Fs *= (1 + eps sgn x1')",
            acts_on: [Main],
            params: {
                eps: "eps", "1", Domain::Open { lower: -1.0, upper: 1.0, text: "(-1, 1)" },
                    "friction asymmetry: Fc, Fs times (1 + eps sgn v1)";
            },
        }
        sensor_lowpass {
            physics: "the sensor reads x1 through a first-order low-pass (tau_sensor)",
            term: "x' = (x1 - x) / tau_sensor (the reading)",
            acts_on: [Reading],
            state: { name: "x_sensor", unit: "m", tau: tau_sensor, follows: Position, scale: Stroke },
            params: {
                tau_sensor: "tau_sensor", "s", Domain::NonNegative, "sensor lag: the reading follows x1 through a first-order low-pass; 0 = off";
            },
        }
        library_force {
            physics: "a force on the main body made of library terms (what `discover` found; off at all zeros)",
            term: "m1 x1'' += lib_x1 x1 + lib_v1 v1 + lib_dx (x1 - x2) + lib_dv (v1 - v2) + lib_sgn tanh(v1/v_s) + lib_abs |v1| + lib_vv v1|v1| + lib_volt V + lib_dvolt V' + lib_t t + lib_x1sq x1^2 + lib_x1cube x1^3 + lib_sin sin(2 pi x1/lib_wavelength) + lib_cos cos(..) + Ff (lib_ff + lib_ff_sin sin(..) + lib_ff_cos cos(..))",
            acts_on: [Main],
            params: {
                lib_x1: "a_x1", "N/m", Domain::Finite, "library force: coefficient of x1";
                lib_v1: "a_v1", "N s/m", Domain::Finite, "library force: coefficient of v1";
                lib_dx: "a_dx", "N/m", Domain::Finite, "library force: coefficient of x1 - x2 (the PE's shortening)";
                lib_dv: "a_dv", "N s/m", Domain::Finite, "library force: coefficient of v1 - v2";
                lib_sgn: "a_sgn", "N", Domain::Finite, "library force: coefficient of sgn v1 (smoothed: tanh(v1/v_s), v_s the Stribeck velocity)";
                lib_abs: "a_abs", "N s/m", Domain::Finite, "library force: coefficient of |v1|";
                lib_vv: "a_vv", "N s^2/m^2", Domain::Finite, "library force: coefficient of v1|v1| (quadratic drag)";
                lib_volt: "a_V", "N/V", Domain::Finite, "library force: coefficient of the PE voltage V";
                lib_dvolt: "a_dV", "N s/V", Domain::Finite, "library force: coefficient of the PE voltage's rate dV/dt";
                lib_t: "a_t", "N/s", Domain::Finite, "library force: coefficient of the time t";
                lib_x1sq: "a_x1^2", "N/m^2", Domain::Finite, "library force: coefficient of x1^2";
                lib_x1cube: "a_x1^3", "N/m^3", Domain::Finite, "library force: coefficient of x1^3 (a cubic spring)";
                lib_sin: "a_sin", "N", Domain::Finite, "library force: coefficient of sin(2 pi x1 / lib_wavelength)";
                lib_cos: "a_cos", "N", Domain::Finite, "library force: coefficient of cos(2 pi x1 / lib_wavelength)";
                lib_ff: "b_ff", "1", Domain::Finite, "library force: coefficient of the friction force Ff (friction scaled by 1 - b_ff)";
                lib_ff_sin: "b_sin", "1", Domain::Finite, "library force: coefficient of Ff sin(2 pi x1 / lib_wavelength) (friction varying with position)";
                lib_ff_cos: "b_cos", "1", Domain::Finite, "library force: coefficient of Ff cos(2 pi x1 / lib_wavelength)";
                lib_wavelength: "lambda", "m", Domain::NonNegative, "library force: the wavelength of its periodic terms in x1; 0 = those terms off";
            },
        }
        library_force_weight {
            physics: "a force on the weight made of library terms (what `discover` found on the weight; off at all zeros)",
            term: "m2 x2'' += libw_x2 x2 + libw_v2 v2 + libw_dx (x2 - x1) + libw_dv (v2 - v1) + libw_sgn tanh(v2/v_s) + libw_vv v2|v2| + libw_volt V + libw_dvolt V'",
            acts_on: [Weight],
            params: {
                libw_x2: "c_x2", "N/m", Domain::Finite, "library force on the weight: coefficient of x2";
                libw_v2: "c_v2", "N s/m", Domain::Finite, "library force on the weight: coefficient of v2";
                libw_dx: "c_dx", "N/m", Domain::Finite, "library force on the weight: coefficient of x2 - x1 (the PE's extension)";
                libw_dv: "c_dv", "N s/m", Domain::Finite, "library force on the weight: coefficient of v2 - v1";
                libw_sgn: "c_sgn", "N", Domain::Finite, "library force on the weight: coefficient of sgn v2 (smoothed: tanh(v2/v_s))";
                libw_vv: "c_vv", "N s^2/m^2", Domain::Finite, "library force on the weight: coefficient of v2|v2|";
                libw_volt: "c_V", "N/V", Domain::Finite, "library force on the weight: coefficient of the PE voltage V";
                libw_dvolt: "c_dV", "N s/V", Domain::Finite, "library force on the weight: coefficient of dV/dt";
            },
        }
        thermal_drift {
            physics: "the reading drifts linearly in time (drift_rate)",
            term: "x = x1 + drift_rate t (the reading)",
            acts_on: [Reading],
            params: {
                drift_rate: "drift_rate", "m/s", Domain::Finite, "linear drift of the reading";
            },
        }
    }
}

impl Effects {
    pub fn set(&mut self, name: &str, value: f64) -> Result<(), InputError> {
        let slot = self
            .slot(name)
            .ok_or_else(|| format!("unknown effect parameter '{name}'; known: {}", EFFECT_NAMES.join(", ")))?;
        *slot = value;
        Ok(())
    }

    /// One parameter by name; None when unknown.
    pub fn get(&self, name: &str) -> Option<f64> {
        let i = EFFECT_NAMES.iter().position(|n| *n == name)?;
        Some(self.values()[i])
    }

    pub fn from_pairs(pairs: &[(&str, f64)]) -> Result<Self, InputError> {
        let mut e = Effects::default();
        for (n, v) in pairs {
            e.set(n, *v)?;
        }
        e.validate()?;
        Ok(e)
    }

    /// Every value finite and in its declared domain; the error names the parameter.
    pub fn validate(&self) -> Result<(), InputError> {
        check_domains("effect parameter", &EFFECT_PARAMS, &self.values())?;
        // a relation between two parameters: a creep amplitude needs a time to creep over
        if self.kappa != 0.0 && self.tau_creep == 0.0 {
            return Err("effect parameter 'kappa' needs a positive 'tau_creep'".into());
        }
        Ok(())
    }

    /// Every lag's time-constant parameter and its value [s] (0: off): a lag much faster than
    /// a fixed step makes its state stiff.
    pub fn lags(&self) -> [(&'static str, f64); N_LAGS] {
        std::array::from_fn(|k| (LAGS[k].tau, self.value_of(LAGS[k].tau).unwrap_or(0.0)))
    }
}

impl<T: Scalar> Effects<T> {
    /// Gravity along the tilted guide on the main body [N], for the device's total mass [kg].
    pub fn incline_force(&self, total_mass: T) -> T {
        -total_mass * GRAVITY * self.theta_rad.sin()
    }

    /// Factor on the normal force from the tilt.
    pub fn normal_scale(&self) -> T {
        self.theta_rad.cos()
    }
}

/// What the library forces read: the states they are functions of, at one instant.
#[derive(Clone, Copy, Debug)]
pub struct LibraryStates<T: Real> {
    /// main body and weight position [m] and velocity [m/s]
    pub x1: T,
    pub v1: T,
    pub x2: T,
    pub v2: T,
    /// PE voltage [V] and its rate [V/s]
    pub volt: T,
    pub dvolt: T,
    /// the friction force on the main body [N]
    pub ff: T,
    /// time [s]
    pub t: T::Value,
    /// the velocity over which sgn v is smoothed (the Stribeck velocity) [m/s]
    pub vs: T,
}

/// |x| deciding the branch on the value (one-sided derivative at 0, as the friction law).
#[inline(always)]
fn magnitude<T: Real>(x: T) -> T {
    T::choose(x.below(0.0), || -x, || x)
}

impl<T: Scalar> Effects<T> {
    /// Whether any library coefficient on the main body, and on the weight, is non-zero (the
    /// wavelength alone switches nothing on).
    pub fn library_on(&self) -> (bool, bool) {
        let main = [
            self.lib_x1,
            self.lib_v1,
            self.lib_dx,
            self.lib_dv,
            self.lib_sgn,
            self.lib_abs,
            self.lib_vv,
            self.lib_volt,
            self.lib_dvolt,
            self.lib_t,
            self.lib_x1sq,
            self.lib_x1cube,
            self.lib_sin,
            self.lib_cos,
            self.lib_ff,
            self.lib_ff_sin,
            self.lib_ff_cos,
        ];
        let weight = [
            self.libw_x2,
            self.libw_v2,
            self.libw_dx,
            self.libw_dv,
            self.libw_sgn,
            self.libw_vv,
            self.libw_volt,
            self.libw_dvolt,
        ];
        let on = |c: &[T]| c.iter().any(|x| !x.is_exactly(0.0));
        (on(&main), on(&weight))
    }
}

impl<T: Real> Effects<T> {
    /// The library force on the main body [N] (`library_force`'s term) and its partials with
    /// respect to [x1, v1, x2, v2, volt, dvolt, ff, t] (for the Jacobian).
    #[inline(always)]
    pub fn library_force_main(&self, s: &LibraryStates<T>) -> (T, [T; 8]) {
        let z = T::zero();
        let (x1, v1) = (s.x1, s.v1);
        let th = (v1 / s.vs).tanh();
        let av = magnitude(v1);
        let sg = T::choose(v1.below(0.0), || -T::one(), T::one);
        let modf = T::one() * self.lib_ff;
        let [per, dper, modf, dmod] = T::choose_n(
            self.lib_wavelength.above(0.0),
            || {
                let k = T::from(2.0 * std::f64::consts::PI) / self.lib_wavelength;
                let (sn, cs) = ((k * x1).sin(), (k * x1).cos());
                [
                    self.lib_sin * sn + self.lib_cos * cs,
                    k * (self.lib_sin * cs - self.lib_cos * sn),
                    modf + self.lib_ff_sin * sn + self.lib_ff_cos * cs,
                    k * (self.lib_ff_sin * cs - self.lib_ff_cos * sn),
                ]
            },
            || [z, z, modf, z],
        );
        let f = self.lib_x1 * x1
            + self.lib_v1 * v1
            + self.lib_dx * (x1 - s.x2)
            + self.lib_dv * (v1 - s.v2)
            + self.lib_sgn * th
            + self.lib_abs * av
            + self.lib_vv * v1 * av
            + self.lib_volt * s.volt
            + self.lib_dvolt * s.dvolt
            + self.lib_t * s.t
            + self.lib_x1sq * x1 * x1
            + self.lib_x1cube * x1 * x1 * x1
            + per
            + s.ff * modf;
        let d_x1 =
            self.lib_x1 + self.lib_dx + self.lib_x1sq * x1 * 2.0 + self.lib_x1cube * x1 * x1 * 3.0 + dper + s.ff * dmod;
        let d_v1 = self.lib_v1
            + self.lib_dv
            + self.lib_sgn * (T::one() - th * th) / s.vs
            + self.lib_abs * sg
            + self.lib_vv * av * 2.0;
        (
            f,
            [
                d_x1,
                d_v1,
                -self.lib_dx,
                -self.lib_dv,
                self.lib_volt,
                self.lib_dvolt,
                modf,
                self.lib_t,
            ],
        )
    }

    /// The library force on the weight [N] (`library_force_weight`'s term) and its partials as
    /// [`Effects::library_force_main`]'s.
    #[inline(always)]
    pub fn library_force_weight(&self, s: &LibraryStates<T>) -> (T, [T; 8]) {
        let z = T::zero();
        let v2 = s.v2;
        let th = (v2 / s.vs).tanh();
        let av = magnitude(v2);
        let f = self.libw_x2 * s.x2
            + self.libw_v2 * v2
            + self.libw_dx * (s.x2 - s.x1)
            + self.libw_dv * (v2 - s.v1)
            + self.libw_sgn * th
            + self.libw_vv * v2 * av
            + self.libw_volt * s.volt
            + self.libw_dvolt * s.dvolt;
        let d_v2 = self.libw_v2 + self.libw_dv + self.libw_sgn * (T::one() - th * th) / s.vs + self.libw_vv * av * 2.0;
        (
            f,
            [
                -self.libw_dx,
                -self.libw_dv,
                self.libw_x2 + self.libw_dx,
                d_v2,
                self.libw_volt,
                self.libw_dvolt,
                z,
                z,
            ],
        )
    }
}

/// What a lag's state follows (its input u in y' = (u - y) / tau).
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum LagInput {
    /// the commanded voltage [V] (an amplifier's output)
    Command,
    /// the creep's equilibrium kappa d33 V_pe [m]
    CreepTarget,
    /// the main body's position x1 [m] (a sensor's reading)
    Position,
}

/// The magnitude a lag state's error is measured against in adaptive error norms.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum LagScale {
    /// the input's peak voltage (at least 1 V)
    Voltage,
    /// the free stroke d33 V_max
    Stroke,
}

/// An effect with a state of its own: a first-order lag y' = (u - y) / tau whose time constant
/// is the effect parameter `tau` (0: the effect and its state are off).
#[derive(Clone, Copy, Debug)]
pub struct LagDecl {
    pub effect: &'static str,
    /// the state's name in `Layout::components` and its unit
    pub state: &'static str,
    pub unit: &'static str,
    pub tau: &'static str,
    pub follows: LagInput,
    pub scale: LagScale,
}

/// Number of lag states.
pub const N_LAGS: usize = LAGS.len();

/// The position in [`LAGS`] of the lag following `input` (a compile error in a `const` when
/// none does).
pub const fn lag_following(input: LagInput) -> usize {
    let mut k = 0;
    while k < LAGS.len() {
        if LAGS[k].follows as u8 == input as u8 {
            return k;
        }
        k += 1;
    }
    panic!("no lag follows this input")
}

/// The amplifier's, the creep's and the sensor's place in [`LAGS`] and `Layout::lags`.
pub const AMPLIFIER: usize = lag_following(LagInput::Command);
pub const CREEP: usize = lag_following(LagInput::CreepTarget);
pub const SENSOR: usize = lag_following(LagInput::Position);

/// Ground spring force on the main body [N].
#[inline(always)]
pub fn ground_spring_force<T: Real>(k_ground: T, x1: T) -> T {
    -k_ground * x1
}

/// Viscous drag on the weight [N].
#[inline(always)]
pub fn weight_drag<T: Real>(c_weight: T, v2: T) -> T {
    -c_weight * v2
}

/// First-order lag dy/dt = (u - y)/tau, used by the amplifier, the creep and the sensor.
#[inline(always)]
pub fn first_order_rate<T: Real>(u: T, y: T, inv_tau: T) -> T {
    (u - y) * inv_tau
}

#[cfg(test)]
#[path = "effects_tests.rs"]
mod tests;
