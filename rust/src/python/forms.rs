//! The engine's own forms handed to Python, so the package writes none of them again: the
//! library's terms along a run (what discovery regresses on, `physics/library_columns.rs`) and a
//! waveform family's breakpoints (`physics/waveform.rs`).

use numpy::{IntoPyArray, PyArray1, PyArrayMethods, PyReadonlyArray1};
use pyo3::prelude::*;

use super::{detached, slice1, value_error};
use crate::batch::WaveFamily;
use crate::physics::effects::LibraryStates;

/// Each library term's force [N] at each sample (samples x terms), the term's coefficient at 1
/// and the periodic terms at `wavelength` [m] (0: off); `vs` [m/s] smooths sgn v.
#[pyfunction]
#[allow(clippy::too_many_arguments)]
#[pyo3(signature = (x1, v1, x2, v2, volt, dvolt, ff, t, vs, wavelength, names))]
fn library_columns<'py>(
    py: Python<'py>,
    x1: PyReadonlyArray1<'py, f64>,
    v1: PyReadonlyArray1<'py, f64>,
    x2: PyReadonlyArray1<'py, f64>,
    v2: PyReadonlyArray1<'py, f64>,
    volt: PyReadonlyArray1<'py, f64>,
    dvolt: PyReadonlyArray1<'py, f64>,
    ff: PyReadonlyArray1<'py, f64>,
    t: PyReadonlyArray1<'py, f64>,
    vs: f64,
    wavelength: f64,
    names: Vec<String>,
) -> PyResult<Bound<'py, PyAny>> {
    let cols = [&x1, &v1, &x2, &v2, &volt, &dvolt, &ff, &t].map(slice1);
    let n = cols[0].len();
    if cols.iter().any(|c| c.len() != n) {
        return Err(value_error(
            "x1, v1, x2, v2, volt, dvolt, ff and t must have the same length",
        ));
    }
    let states: Vec<LibraryStates<f64>> = (0..n)
        .map(|i| LibraryStates {
            x1: cols[0][i],
            v1: cols[1][i],
            x2: cols[2][i],
            v2: cols[3][i],
            volt: cols[4][i],
            dvolt: cols[5][i],
            ff: cols[6][i],
            t: cols[7][i],
            vs,
        })
        .collect();
    let k = names.len();
    let out = detached(py, move || {
        let names: Vec<&str> = names.iter().map(String::as_str).collect();
        crate::physics::library_columns::library_columns(&states, &names, wavelength)
    })?
    .map_err(|e| value_error(e.to_string()))?;
    Ok(out.into_pyarray(py).reshape([n, k])?.into_any())
}

/// The library's terms on the main body and on the weight, as the catalogue declares them.
#[pyfunction]
fn library_terms() -> (Vec<&'static str>, Vec<&'static str>) {
    crate::physics::library_columns::library_terms()
}

/// Two numpy arrays of the same length.
type ArrayPair<'py> = (Bound<'py, PyArray1<f64>>, Bound<'py, PyArray1<f64>>);

/// The breakpoints (t [s], V [V]) of a `kind` ("triangle", "sawtooth") waveform with per-point
/// `fields` in `wave_fields(kind)` order, as the engine builds its input.
#[pyfunction]
fn wave_breakpoints<'py>(py: Python<'py>, kind: &str, fields: Vec<f64>) -> PyResult<ArrayPair<'py>> {
    let family = WaveFamily::new(kind, None).map_err(|e| value_error(e.to_string()))?;
    if fields.len() != family.fields().len() {
        return Err(value_error(format!(
            "a {kind} waveform has the fields {:?}, got {} values",
            family.fields(),
            fields.len()
        )));
    }
    let (wave, _) = family.build(&fields).map_err(|e| value_error(e.to_string()))?;
    Ok((
        wave.times().to_vec().into_pyarray(py),
        wave.values().to_vec().into_pyarray(py),
    ))
}

pub(super) fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_function(wrap_pyfunction!(library_columns, m)?)?;
    m.add_function(wrap_pyfunction!(library_terms, m)?)?;
    m.add_function(wrap_pyfunction!(wave_breakpoints, m)?)?;
    Ok(())
}
