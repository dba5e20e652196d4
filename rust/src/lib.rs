//! idm-rs core: dynamics of a piezoelectric impact drive mechanism (IDM). Each folder is one
//! layer and uses only the layers listed above it:
//!
//! - [`numbers`]: the number types the physics is written over (f64, duals, lane vectors);
//! - [`physics`]: parameters, input voltage and every force law (friction, piezo, mechanisms, effects);
//! - [`model`]: the IDM as one first-order system (state layout, right-hand side, Jacobian);
//! - [`integrate`]: what a run is, and the integrators (RK4, Dormand-Prince, Rodas4, auto);
//! - [`lanes`]: the same integrators over `L` runs at once on vector lanes;
//! - [`drive`]: the one driver every run goes through (groups runs onto lanes or runs them one by one);
//! - [`simulate`], [`sensitivity`], [`batch`]: one saved run, exact derivatives, many points in parallel;
//! - [`watch`]: a run on its own thread while the caller looks for Ctrl-C;
//! - [`gpu`] (the CUDA kernel's constants) and `python` (the PyO3 binding, `python` feature).

pub mod batch;
pub mod drive;
pub mod error;
pub mod gpu;
pub mod integrate;
pub mod lanes;
pub mod model;
pub mod numbers;
pub mod physics;
pub mod sensitivity;
pub mod simulate;
pub mod watch;

#[cfg(test)]
mod paper_case_tests;

#[cfg(feature = "python")]
mod python;
