//! Read-only descriptions of the model for the Python side (Table 1, the effect catalogue, the
//! structures, the methods, gravity: units, bounds, catalogue text), registered by [`register`]
//! in the module's init.

use pyo3::prelude::*;
use pyo3::types::PyDict;

use crate::integrate::method::METHODS;
use crate::physics::declare::ParamDecl;
use crate::physics::effects::EFFECTS;
use crate::physics::mechanics::STRUCTURES;
use crate::physics::params::{GRAVITY, TABLE1};

/// One declared quantity as a dict: name, symbol, unit, meaning, domain (lower, upper,
/// lower_closed, rule) and value (None where Table 1 derives it).
fn param_dict<'py>(py: Python<'py>, d: &ParamDecl) -> PyResult<Bound<'py, PyDict>> {
    let out = PyDict::new(py);
    out.set_item("name", d.name)?;
    out.set_item("symbol", d.symbol)?;
    out.set_item("unit", d.unit)?;
    out.set_item("meaning", d.meaning)?;
    out.set_item("lower", d.domain.lower())?;
    out.set_item("upper", d.domain.upper())?;
    out.set_item("lower_closed", d.domain.lower_closed())?;
    out.set_item("rule", d.domain.rule())?;
    let value = (!d.value.is_nan()).then_some(d.value); // NaN: derived
    out.set_item("value", value)?;
    Ok(out)
}

/// Table 1, in the order of `param_names()`.
#[pyfunction]
fn param_declarations(py: Python<'_>) -> PyResult<Vec<Bound<'_, PyDict>>> {
    TABLE1.iter().map(|d| param_dict(py, d)).collect()
}

/// The effect catalogue: id, kind ("term", "structure", "parameter"), physics, term, params.
#[pyfunction]
fn effect_declarations(py: Python<'_>) -> PyResult<Vec<Bound<'_, PyDict>>> {
    EFFECTS
        .iter()
        .map(|e| {
            let out = PyDict::new(py);
            out.set_item("id", e.id)?;
            out.set_item("kind", e.kind.name())?;
            out.set_item("physics", e.physics)?;
            out.set_item("term", e.term)?;
            let params: PyResult<Vec<_>> = e.params.iter().map(|d| param_dict(py, d)).collect();
            out.set_item("params", params?)?;
            Ok(out)
        })
        .collect()
}

/// The structures (`model` names): name, label, meaning, elements (takes `n_elements`), idm.
#[pyfunction]
fn structure_declarations(py: Python<'_>) -> PyResult<Vec<Bound<'_, PyDict>>> {
    STRUCTURES
        .iter()
        .map(|s| {
            let out = PyDict::new(py);
            out.set_item("name", s.name)?;
            out.set_item("label", s.label)?;
            out.set_item("meaning", s.meaning)?;
            out.set_item("elements", s.elements)?;
            out.set_item("idm", s.idm)?;
            Ok(out)
        })
        .collect()
}

/// The integration methods: name, adaptive (chooses its own steps), meaning, kernel (the GPU
/// kernel backends run it).
#[pyfunction]
fn method_declarations(py: Python<'_>) -> PyResult<Vec<Bound<'_, PyDict>>> {
    METHODS
        .iter()
        .map(|d| {
            let out = PyDict::new(py);
            out.set_item("name", d.name)?;
            out.set_item("adaptive", d.adaptive)?;
            out.set_item("meaning", d.meaning)?;
            out.set_item("kernel", d.kernel)?;
            Ok(out)
        })
        .collect()
}

pub(super) fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_function(wrap_pyfunction!(method_declarations, m)?)?;
    m.add_function(wrap_pyfunction!(structure_declarations, m)?)?;
    m.add_function(wrap_pyfunction!(param_declarations, m)?)?;
    m.add_function(wrap_pyfunction!(effect_declarations, m)?)?;
    // standard gravity [m/s^2] of the default normal force
    m.add("GRAVITY", GRAVITY)?;
    Ok(())
}
