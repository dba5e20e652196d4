//! idm-rs core: dynamics of a piezoelectric impact drive mechanism (IDM).
//!
//! One physical idea per module; the numerics are plain Rust, testable with `cargo test`.
//! The Python bindings (`python` feature) are a thin layer in `bindings`.

pub mod batch;
pub mod crawl;
pub mod declare;
pub mod dopri5;
pub mod drive;
pub mod effects;
pub mod external_force;
pub mod friction;
pub mod jacobian;
pub mod fast_exp;
pub mod kernel;
pub mod lane_real;
pub mod lanes;
pub mod lanes_dopri5;
pub mod lanes_rk4;
pub mod mechanics;
pub mod model;
pub mod params;
pub mod piezo;
pub mod rig;
pub mod real;
pub mod rk4;
pub mod rodas4;
pub mod scalar;
pub mod sensitivity;
pub mod simulate;
pub mod stepper;
pub mod stiffness;
pub mod switching;
pub mod tangent;
pub mod waveform;

#[cfg(test)]
mod paper_case_tests;

#[cfg(feature = "python")]
mod bindings;
