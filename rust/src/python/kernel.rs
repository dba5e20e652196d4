//! The GPU kernel's side of the binding: the generated right-hand side with each point's
//! constants (`gpu/generate.rs`), the tableaus as C `#define`s, and what the kernel admits
//! (`gpu/kernel.rs`).

use numpy::{IntoPyArray, PyArrayMethods, PyReadonlyArray2, PyUntypedArrayMethods};
use pyo3::prelude::*;

use super::*;
use crate::gpu::generate::Generated;

/// The GPU kernel's program for points of one shape: the generated layout `#define`s and
/// right-hand side `idm_rhs` (C source traced from the engine's model of the first point) and
/// every point's constants row. `params` (P, len(param_names())) in `param_names()` order, NaN
/// normal_force = derived; `effects` (P, len(effect_names())). Refuses, naming the point, what the
/// kernel cannot run and a point whose state differs from the first's.
#[pyfunction]
fn kernel_program<'py>(
    py: Python<'py>,
    config: &RunConfig,
    params: PyReadonlyArray2<'_, f64>,
    effects: PyReadonlyArray2<'_, f64>,
) -> PyResult<(String, String, Bound<'py, PyAny>)> {
    let rows = params.shape()[0];
    if rows == 0 || effects.shape()[0] != rows {
        return Err(value_error(format!(
            "kernel_program needs one effects row per parameter row and at least one point; got {rows} and {}",
            effects.shape()[0]
        )));
    }
    let (p, e) = (slice2(&params), slice2(&effects));
    let (np, ne) = (PARAM_NAMES.len(), EFFECT_NAMES.len());
    let model = |r: usize| -> PyResult<Model> {
        let (pp, ee, _) = crate::batch::row_point(&p[r * np..(r + 1) * np], &e[r * ne..(r + 1) * ne])
            .map_err(|err| value_error(format!("point {r}: {err}")))?;
        config.model(pp, ee, false)
    };
    let program = Generated::trace(&model(0)?).map_err(|err| value_error(format!("point 0: {err}")))?;
    let mut out = Vec::with_capacity(rows * program.row_len());
    for r in 0..rows {
        out.extend(
            program
                .constants(&model(r)?)
                .map_err(|err| value_error(format!("point {r}: {err}")))?,
        );
    }
    let consts = out.into_pyarray(py).reshape([rows, program.row_len()])?.into_any();
    Ok((program.layout, program.rhs, consts))
}

/// What the GPU kernel implements (`rust/src/gpu/kernel.rs`): the Table 1 parameters, effects,
/// waveform families (with their fields), structures, metrics and methods (`METHODS`' `kernel`)
/// it admits, and its largest node count; the kernel backends refuse everything else by name.
#[pyfunction]
fn kernel_accepts(py: Python<'_>) -> PyResult<Bound<'_, pyo3::types::PyDict>> {
    let d = pyo3::types::PyDict::new(py);
    // the right-hand side is generated from the model: every parameter and effect is in it
    d.set_item("params", PARAM_NAMES.to_vec())?;
    d.set_item("effects", EFFECT_NAMES.to_vec())?;
    let waves = pyo3::types::PyDict::new(py);
    for (kind, fields) in crate::gpu::kernel::WAVES {
        waves.set_item(kind, fields.to_vec())?;
    }
    d.set_item("waves", waves)?;
    d.set_item("structures", crate::gpu::kernel::structures())?;
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

/// The C `#define`s every kernel specialisation shares (`rust/src/gpu/kernel.rs`: the crawl
/// limits and the tableaus), to put in front of the kernel source when it is compiled.
#[pyfunction]
fn kernel_header() -> String {
    crate::gpu::kernel::kernel_header()
}

pub(super) fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_function(wrap_pyfunction!(kernel_program, m)?)?;
    m.add_function(wrap_pyfunction!(kernel_header, m)?)?;
    m.add_function(wrap_pyfunction!(kernel_accepts, m)?)?;
    Ok(())
}
