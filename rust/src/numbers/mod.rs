//! The number types the physics is written over: one `f64` ([`scalar::Scalar`] for plain runs),
//! forward-mode duals and tangents for derivatives ([`real::Real`], [`tangent`]), and `L` `f64`
//! lanes at once ([`lane_real`], with a vectorisable `exp` in [`fast_exp`]).

pub mod fast_exp;
pub mod lane_real;
pub mod real;
pub mod scalar;
pub mod symbolic;
pub mod tangent;
