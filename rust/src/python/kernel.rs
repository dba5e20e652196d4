//! The GPU kernel's side of the binding: each point's constants, their layout and the tableaus as
//! C `#define`s, and what the kernel admits (`gpu/kernel.rs`).

use numpy::{IntoPyArray, PyArrayMethods, PyReadonlyArray2, PyUntypedArrayMethods};
use pyo3::prelude::*;

use super::*;

/// The GPU kernel's constants of every point: `params` (P, len(param_names())) in
/// `param_names()` order, NaN normal_force = derived; returns (P, kernel_constant_count()).
/// Refuses (naming the row) a point the kernel cannot run.
#[pyfunction]
fn kernel_constants<'py>(
    py: Python<'py>,
    config: &RunConfig,
    params: PyReadonlyArray2<'_, f64>,
) -> PyResult<Bound<'py, PyAny>> {
    let rows = params.shape()[0];
    let table = slice2(&params);
    let np = PARAM_NAMES.len();
    let mut out = Vec::with_capacity(rows * crate::gpu::kernel::N_CONSTANTS);
    for r in 0..rows {
        let pairs: Vec<(&str, f64)> = PARAM_NAMES
            .iter()
            .copied()
            .zip(table[r * np..(r + 1) * np].iter().copied())
            .filter(|(name, v)| !(*name == "normal_force" && v.is_nan()))
            .collect();
        let p = Params::from_pairs(&pairs).map_err(|e| value_error(format!("point {r}: {e}")))?;
        let m = config.model(p, Effects::default(), false)?;
        out.extend(crate::gpu::kernel::kernel_constants(&m).map_err(|e| value_error(format!("point {r}: {e}")))?);
    }
    Ok(out
        .into_pyarray(py)
        .reshape([rows, crate::gpu::kernel::N_CONSTANTS])?
        .into_any())
}

/// Number of constants per point of the GPU kernel (its layout is `rust/src/gpu/kernel.rs`).
#[pyfunction]
fn kernel_constant_count() -> (usize, usize, usize) {
    (
        crate::gpu::kernel::N_CONSTANTS,
        crate::gpu::kernel::N_SCALARS,
        crate::gpu::kernel::MAX_DOF,
    )
}

/// What the GPU kernel implements (`rust/src/gpu/kernel.rs`): the Table 1 parameters, effects,
/// waveform families (with their fields), structures, metrics and methods (`METHODS`' `kernel`)
/// it admits, and its largest node count; the kernel backends refuse everything else by name.
#[pyfunction]
fn kernel_accepts(py: Python<'_>) -> PyResult<Bound<'_, pyo3::types::PyDict>> {
    let d = pyo3::types::PyDict::new(py);
    d.set_item("params", crate::gpu::kernel::PARAMS.to_vec())?;
    d.set_item("effects", crate::gpu::kernel::EFFECTS.to_vec())?;
    let waves = pyo3::types::PyDict::new(py);
    for (kind, fields) in crate::gpu::kernel::WAVES {
        waves.set_item(kind, fields.to_vec())?;
    }
    d.set_item("waves", waves)?;
    d.set_item("structures", crate::gpu::kernel::STRUCTURES.to_vec())?;
    d.set_item("metrics", crate::gpu::kernel::METRICS.to_vec())?;
    d.set_item("max_dof", crate::gpu::kernel::MAX_DOF)?;
    let methods: Vec<&str> = crate::integrate::method::METHODS
        .iter()
        .filter(|m| m.kernel)
        .map(|m| m.name)
        .collect();
    d.set_item("methods", methods)?;
    Ok(d)
}

/// The C `#define`s of the kernel's constants' layout (`rust/src/gpu/kernel.rs`), to put in front
/// of the kernel source when it is compiled.
#[pyfunction]
fn kernel_header() -> String {
    crate::gpu::kernel::kernel_header()
}

pub(super) fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_function(wrap_pyfunction!(kernel_constants, m)?)?;
    m.add_function(wrap_pyfunction!(kernel_constant_count, m)?)?;
    m.add_function(wrap_pyfunction!(kernel_header, m)?)?;
    m.add_function(wrap_pyfunction!(kernel_accepts, m)?)?;
    Ok(())
}
