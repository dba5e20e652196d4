//! Which integrator a run uses, with its settings, validated; and the methods declared once
//! ([`METHODS`]), the list the binding and the Python package read.

use crate::error::InputError;

/// An integration method as a user names it: its name, whether it chooses its own steps
/// (`rtol`, `atol`) rather than taking `dt`, what it is, and whether the GPU kernel has it (the
/// kernel backends admit only these: `kernel_accepts`; `auto` runs there as Dormand-Prince, a
/// point that turns stiff rerun on the CPU).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct MethodDecl {
    pub name: &'static str,
    pub adaptive: bool,
    pub meaning: &'static str,
    pub kernel: bool,
}

/// Every method, the reference first.
pub const METHODS: &[MethodDecl] = &[
    MethodDecl {
        name: "rk4",
        adaptive: false,
        meaning: "fixed-step classical Runge-Kutta 4 (the reference)",
        kernel: true,
    },
    MethodDecl {
        name: "dopri5",
        adaptive: true,
        meaning: "Dormand-Prince 5(4), explicit, adaptive",
        kernel: true,
    },
    MethodDecl {
        name: "rodas4",
        adaptive: true,
        meaning: "Rodas4, linearly implicit, L-stable, adaptive",
        kernel: false,
    },
    MethodDecl {
        name: "auto",
        adaptive: true,
        meaning: "Dormand-Prince, switching a run that turns stiff to Rodas4 and back",
        kernel: true,
    },
];

/// Integration method of a run.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Method {
    /// Fixed-step classical RK4 with step `dt` [s] (the reference).
    Rk4 { dt: f64 },
    /// Adaptive Dormand-Prince 5(4); `atol` in units of each state's natural scale (see
    /// [`Model::state_scales`]), `first_step` [s] the first trial step.
    Dopri5 { rtol: f64, atol: f64, first_step: f64 },
    /// Adaptive Rodas4 (linearly implicit, L-stable: steps set by accuracy in the stiff sliding
    /// phases); tolerances and first step as for `Dopri5`.
    Rodas4 { rtol: f64, atol: f64, first_step: f64 },
    /// Dormand-Prince at `rtol`, `atol`; a run that turns stiff tries a Rodas4 step (tolerances
    /// `switching::IMPLICIT_TOL_FACTOR` times looser) and goes on with Rodas4 if it pays
    /// (`integrate/stiffness.rs`, `integrate/switching.rs`).
    Auto { rtol: f64, atol: f64, first_step: f64 },
}

impl Method {
    /// The method called `name` (one of [`METHODS`]) with these settings, validated.
    pub fn from_name(name: &str, dt: f64, rtol: f64, atol: f64, first_step: f64) -> Result<Self, InputError> {
        let m = match name {
            "rk4" => Method::Rk4 { dt },
            "dopri5" => Method::Dopri5 { rtol, atol, first_step },
            "rodas4" => Method::Rodas4 { rtol, atol, first_step },
            "auto" => Method::Auto { rtol, atol, first_step },
            other => {
                let names: Vec<String> = METHODS.iter().map(|d| format!("'{}'", d.name)).collect();
                return Err(crate::input!(
                    "parameter 'method' must be one of {}, got '{other}'",
                    names.join(", ")
                ));
            }
        };
        m.validate()?;
        Ok(m)
    }

    /// The fixed step [s] of a fixed-step method (RK4); `None` for an adaptive one.
    pub fn fixed_step(&self) -> Option<f64> {
        match *self {
            Method::Rk4 { dt } => Some(dt),
            Method::Dopri5 { .. } | Method::Rodas4 { .. } | Method::Auto { .. } => None,
        }
    }

    /// The same fixed-step method with step `dt` [s] (a retry's halved step, a derivative
    /// pass at the step a retry used); `None` for an adaptive method, which has no step to set.
    pub fn with_step(&self, dt: f64) -> Option<Method> {
        match *self {
            Method::Rk4 { .. } => Some(Method::Rk4 { dt }),
            Method::Dopri5 { .. } | Method::Rodas4 { .. } | Method::Auto { .. } => None,
        }
    }

    /// Whether every step is the same, set beforehand (RK4).
    pub fn is_fixed(&self) -> bool {
        self.fixed_step().is_some()
    }

    /// The first step [s]: RK4's step, or an adaptive method's first trial step.
    pub fn first_step(&self) -> f64 {
        match *self {
            Method::Rk4 { dt } => dt,
            Method::Dopri5 { first_step, .. } | Method::Rodas4 { first_step, .. } | Method::Auto { first_step, .. } => {
                first_step
            }
        }
    }

    /// Refuse tolerances or steps that are not positive and finite.
    pub fn validate(&self) -> Result<(), InputError> {
        match *self {
            Method::Rk4 { dt } => {
                if !(dt.is_finite() && dt > 0.0) {
                    return Err(crate::input!("parameter 'dt' must be positive and finite, got {dt}"));
                }
            }
            Method::Dopri5 { rtol, atol, first_step }
            | Method::Rodas4 { rtol, atol, first_step }
            | Method::Auto { rtol, atol, first_step } => {
                if !(rtol > 0.0 && atol > 0.0 && rtol.is_finite() && atol.is_finite()) {
                    return Err(crate::input!("'rtol' and 'atol' must be positive, got {rtol}, {atol}"));
                }
                if !(first_step.is_finite() && first_step > 0.0) {
                    return Err(crate::input!(
                        "parameter 'first_step' must be positive and finite, got {first_step}"
                    ));
                }
            }
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_declared_method_is_built_by_its_name_and_declares_whether_it_is_adaptive() {
        for d in METHODS {
            let m = Method::from_name(d.name, 1e-8, 1e-6, 1e-6, 1e-9).unwrap_or_else(|e| panic!("{}: {e}", d.name));
            assert_eq!(d.adaptive, !m.is_fixed(), "{}", d.name);
        }
        let err = Method::from_name("euler", 1e-8, 1e-6, 1e-6, 1e-9).unwrap_err();
        assert!(METHODS.iter().all(|d| err.contains(&format!("'{}'", d.name))), "{err}");
    }
}
