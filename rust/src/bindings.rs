//! Thin PyO3 layer: converts Python values, releases the GIL, calls the pure-Rust core, and maps
//! errors to Python exceptions. No numerics here.

use std::collections::HashMap;
use std::panic::{catch_unwind, AssertUnwindSafe};

use numpy::{IntoPyArray, PyArray1, PyArrayMethods};
use pyo3::create_exception;
use pyo3::exceptions::{PyRuntimeError, PyValueError};
use pyo3::prelude::*;
use pyo3::types::PyDict;

use crate::effects::{Effects, EFFECT_NAMES};
use crate::mechanics::Structure;
use crate::model::{Model, N_ACCOUNTING};
use crate::params::{Params, PARAM_NAMES};
use crate::simulate::{simulate as simulate_core, SimError};
use crate::waveform::PiecewiseLinear;

create_exception!(_core, DivergenceError, PyRuntimeError, "The integration left its physical bounds (a step too large, usually).");

fn value_error(msg: String) -> PyErr {
    PyValueError::new_err(msg)
}

fn sim_error(e: SimError) -> PyErr {
    match e {
        SimError::Input(m) => PyValueError::new_err(m),
        SimError::Diverged { t, message } => DivergenceError::new_err((message, t)),
    }
}

/// Run `f` with the GIL released; a panic becomes a RuntimeError instead of tearing down Python.
fn detached<T: Send, F: FnOnce() -> T + Send>(py: Python<'_>, f: F) -> PyResult<T> {
    py.detach(|| catch_unwind(AssertUnwindSafe(f))).map_err(|p| {
        let what = p
            .downcast_ref::<String>()
            .cloned()
            .or_else(|| p.downcast_ref::<&str>().map(|s| s.to_string()))
            .unwrap_or_else(|| "unknown panic".into());
        PyRuntimeError::new_err(format!("internal error in idm-rs core (please report): {what}"))
    })
}

pub(crate) fn parse_params(params: &HashMap<String, f64>) -> PyResult<Params> {
    let pairs: Vec<(&str, f64)> = params.iter().map(|(k, v)| (k.as_str(), *v)).collect();
    Params::from_pairs(&pairs).map_err(value_error)
}

pub(crate) fn parse_effects(effects: &HashMap<String, f64>) -> PyResult<Effects> {
    let pairs: Vec<(&str, f64)> = effects.iter().map(|(k, v)| (k.as_str(), *v)).collect();
    Effects::from_pairs(&pairs).map_err(value_error)
}

pub(crate) fn parse_structure(model: &str, n_elements: usize) -> PyResult<Structure> {
    match model {
        "lps" => Ok(Structure::Lps),
        "dps" if n_elements >= 1 => Ok(Structure::Dps(n_elements)),
        "dps" => Err(value_error(format!("parameter 'n_elements' must be at least 1, got {n_elements}"))),
        other => Err(value_error(format!("parameter 'model' must be 'lps' or 'dps', got '{other}'"))),
    }
}

/// Table 1 overridden by `params`, with the derived normal force filled in.
#[pyfunction]
fn resolve_params(params: HashMap<String, f64>) -> PyResult<HashMap<String, f64>> {
    let p = parse_params(&params)?;
    Ok(PARAM_NAMES.iter().map(|n| (n.to_string(), p.get(n).unwrap())).collect())
}

#[pyfunction]
fn param_names() -> Vec<&'static str> {
    PARAM_NAMES.to_vec()
}

#[pyfunction]
fn effect_names() -> Vec<&'static str> {
    EFFECT_NAMES.to_vec()
}

/// Highest structural natural frequency [rad/s] of the model.
#[pyfunction]
#[pyo3(signature = (params, model, n_elements))]
fn highest_frequency(params: HashMap<String, f64>, model: &str, n_elements: usize) -> PyResult<f64> {
    let p = parse_params(&params)?;
    let m = Model::new(p, Effects::default(), parse_structure(model, n_elements)?, false, false).map_err(value_error)?;
    Ok(m.mech.highest_frequency())
}

/// Simulate one run; returns a dict of numpy arrays (see `idm_rs.simulate`).
#[pyfunction]
#[pyo3(signature = (params, effects, wave_t, wave_v, t_end, dt, model, n_elements, save_every, piezo_hysteresis, energy))]
#[allow(clippy::too_many_arguments)]
fn simulate<'py>(
    py: Python<'py>,
    params: HashMap<String, f64>,
    effects: HashMap<String, f64>,
    wave_t: Vec<f64>,
    wave_v: Vec<f64>,
    t_end: f64,
    dt: f64,
    model: &str,
    n_elements: usize,
    save_every: usize,
    piezo_hysteresis: bool,
    energy: bool,
) -> PyResult<Bound<'py, PyDict>> {
    let p = parse_params(&params)?;
    let e = parse_effects(&effects)?;
    let structure = parse_structure(model, n_elements)?;
    let wave = PiecewiseLinear::new(wave_t, wave_v).map_err(value_error)?;
    let m = Model::new(p, e, structure, piezo_hysteresis, energy).map_err(value_error)?;
    let traj = detached(py, || simulate_core(&m, &wave, t_end, dt, save_every))?.map_err(sim_error)?;

    let nt = traj.t.len();
    let dof = traj.dof;
    let d = PyDict::new(py);
    let arr2 = |v: Vec<f64>, cols: usize| -> PyResult<Bound<'py, PyAny>> {
        Ok(PyArray1::from_vec(py, v).reshape([nt, cols])?.into_any())
    };
    d.set_item("t", traj.t.into_pyarray(py))?;
    d.set_item("nodes", arr2(traj.nodes, dof)?)?;
    d.set_item("velocities", arr2(traj.velocities, dof)?)?;
    d.set_item("g", traj.g.into_pyarray(py))?;
    d.set_item("fh", traj.fh.into_pyarray(py))?;
    d.set_item("h", traj.h.into_pyarray(py))?;
    d.set_item("friction", traj.friction.into_pyarray(py))?;
    d.set_item("piezo_force", traj.piezo_force.into_pyarray(py))?;
    d.set_item("voltage", traj.voltage.into_pyarray(py))?;
    d.set_item("reading", traj.reading.into_pyarray(py))?;
    d.set_item("final_state", traj.final_state.into_pyarray(py))?;
    if energy {
        d.set_item("accounting", arr2(traj.accounting, N_ACCOUNTING)?)?;
        d.set_item("kinetic", traj.kinetic.into_pyarray(py))?;
        d.set_item("strain", traj.strain.into_pyarray(py))?;
        d.set_item("momentum", traj.momentum.into_pyarray(py))?;
    }
    Ok(d)
}

#[pymodule]
fn _core(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add("DivergenceError", m.py().get_type::<DivergenceError>())?;
    m.add_function(wrap_pyfunction!(simulate, m)?)?;
    m.add_function(wrap_pyfunction!(resolve_params, m)?)?;
    m.add_function(wrap_pyfunction!(param_names, m)?)?;
    m.add_function(wrap_pyfunction!(effect_names, m)?)?;
    m.add_function(wrap_pyfunction!(highest_frequency, m)?)?;
    m.add("__version__", env!("CARGO_PKG_VERSION"))?;
    Ok(())
}
