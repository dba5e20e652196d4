//! Thin PyO3 layer: converts Python values, releases the GIL, calls the pure-Rust core, and maps
//! errors to Python exceptions. No numerics here.

use std::collections::HashMap;
use std::panic::{catch_unwind, AssertUnwindSafe};
use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};
use std::sync::{Arc, Mutex};
use std::thread::JoinHandle;

use numpy::{IntoPyArray, PyArray1, PyArrayMethods, PyReadonlyArray2, PyUntypedArrayMethods};
use pyo3::create_exception;
use pyo3::exceptions::{PyRuntimeError, PyValueError};
use pyo3::prelude::*;
use pyo3::types::PyDict;

use crate::batch::{run_batch, BatchConfig, Method, PointMetrics, PointOutput, PointSpec, Status};
use crate::effects::{Effects, EFFECT_NAMES};
use crate::mechanics::Structure;
use crate::model::{Model, N_ACCOUNTING};
use crate::params::{Params, PARAM_NAMES};
use crate::simulate::{plan_steps, simulate as simulate_core, SimError};
use crate::waveform::PiecewiseLinear;

create_exception!(
    _core,
    DivergenceError,
    PyRuntimeError,
    "The integration left its physical bounds (a step too large, usually)."
);

fn value_error(msg: String) -> PyErr {
    PyValueError::new_err(msg)
}

fn sim_error(py: Python<'_>, e: SimError) -> PyErr {
    match e {
        SimError::Input(m) => PyValueError::new_err(m),
        SimError::Diverged { t, message } => {
            let err = DivergenceError::new_err(message);
            // the time [s] as an attribute, so callers need not parse the message
            let _ = err.value(py).setattr("t", t);
            err
        }
    }
}

/// Run `f` with the GIL released; a panic becomes a RuntimeError instead of tearing down Python.
fn detached<T: Send, F: FnOnce() -> T + Send>(py: Python<'_>, f: F) -> PyResult<T> {
    py.detach(|| catch_unwind(AssertUnwindSafe(f)))
        .map_err(|p| {
            let what = p
                .downcast_ref::<String>()
                .cloned()
                .or_else(|| p.downcast_ref::<&str>().map(|s| s.to_string()))
                .unwrap_or_else(|| "unknown panic".into());
            PyRuntimeError::new_err(format!(
                "internal error in idm-rs core (please report): {what}"
            ))
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
        "dps" => Err(value_error(format!(
            "parameter 'n_elements' must be at least 1, got {n_elements}"
        ))),
        other => Err(value_error(format!(
            "parameter 'model' must be 'lps' or 'dps', got '{other}'"
        ))),
    }
}

/// Table 1 overridden by `params`, with the derived normal force filled in.
#[pyfunction]
fn resolve_params(params: HashMap<String, f64>) -> PyResult<HashMap<String, f64>> {
    let p = parse_params(&params)?;
    Ok(PARAM_NAMES
        .iter()
        .map(|n| (n.to_string(), p.get(n).unwrap()))
        .collect())
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
fn highest_frequency(
    params: HashMap<String, f64>,
    model: &str,
    n_elements: usize,
) -> PyResult<f64> {
    let p = parse_params(&params)?;
    let m = Model::new(
        p,
        Effects::default(),
        parse_structure(model, n_elements)?,
        false,
        false,
    )
    .map_err(value_error)?;
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
    let traj = detached(py, || simulate_core(&m, &wave, t_end, dt, save_every))?
        .map_err(|e| sim_error(py, e))?;

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

/// Columns of the per-point waveform matrix given to `start_batch`.
const WAVE_COLUMNS: [&str; 8] = [
    "kind",
    "amplitude",
    "rise",
    "fall",
    "frequency",
    "cycles",
    "forward",
    "delay",
];

fn point_wave(
    row: &[f64],
    sampled: &Option<(Vec<f64>, Vec<f64>)>,
) -> Result<(PiecewiseLinear, usize), String> {
    let [kind, amplitude, rise, fall, frequency, cycles, forward, delay] = row.try_into().unwrap();
    match kind as i64 {
        0 => Ok((PiecewiseLinear::triangle(amplitude, rise, fall, delay)?, 0)),
        1 => {
            if !(cycles >= 1.0 && cycles.fract() == 0.0) {
                return Err(format!(
                    "parameter 'cycles' must be a positive integer, got {cycles}"
                ));
            }
            let c = cycles as usize;
            Ok((
                PiecewiseLinear::sawtooth(amplitude, frequency, c, rise, forward != 0.0, delay)?,
                c,
            ))
        }
        _ => {
            // a shared sampled waveform, scaled by the point's `amplitude` (1 = as given)
            let (t, v) = sampled.as_ref().ok_or("sampled waveform missing")?;
            Ok((
                PiecewiseLinear::new(t.clone(), v.iter().map(|x| x * amplitude).collect())?,
                0,
            ))
        }
    }
}

type BatchOutcome = Result<Vec<PointOutput>, String>;

/// A batch running on a background thread (with its own rayon pool), so that Python can show
/// progress and cancel it on Ctrl-C while the GIL is free.
#[pyclass(module = "idm_rs._core")]
struct BatchRun {
    cancel: Arc<AtomicBool>,
    done: Arc<AtomicUsize>,
    total: usize,
    handle: Mutex<Option<JoinHandle<BatchOutcome>>>,
}

#[pymethods]
impl BatchRun {
    /// Points finished so far.
    fn progress(&self) -> usize {
        self.done.load(Ordering::Relaxed)
    }

    #[getter]
    fn total(&self) -> usize {
        self.total
    }

    /// Ask the workers to stop; points already finished are kept.
    fn cancel(&self) {
        self.cancel.store(true, Ordering::Relaxed);
    }

    /// Wait up to `timeout` seconds (GIL released); True when the batch has finished.
    fn wait(&self, py: Python<'_>, timeout: f64) -> bool {
        let finished = || {
            self.handle
                .lock()
                .unwrap()
                .as_ref()
                .map_or(true, |h| h.is_finished())
        };
        let deadline =
            std::time::Instant::now() + std::time::Duration::from_secs_f64(timeout.max(0.0));
        py.detach(|| loop {
            if finished() {
                return true;
            }
            if std::time::Instant::now() >= deadline {
                return false;
            }
            std::thread::sleep(std::time::Duration::from_millis(5));
        })
    }

    /// Join and return the metrics as a dict of arrays (NaN / status 0 for points not run).
    fn result<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        let handle = self
            .handle
            .lock()
            .unwrap()
            .take()
            .ok_or_else(|| PyRuntimeError::new_err("result already taken"))?;
        let outcome = py.detach(|| handle.join()).map_err(|_| {
            PyRuntimeError::new_err("internal error in idm-rs batch worker (please report)")
        })?;
        let outputs = outcome.map_err(value_error)?;
        let d = PyDict::new(py);
        if outputs.iter().any(|o| !o.trace.is_empty()) {
            let traces = pyo3::types::PyList::empty(py);
            for o in &outputs {
                traces.append(PyArray1::from_slice(py, &o.trace))?;
            }
            d.set_item("traces", traces)?;
        }
        let metrics: Vec<PointMetrics> = outputs.into_iter().map(|o| o.metrics).collect();
        let col = |f: fn(&PointMetrics) -> f64| metrics.iter().map(f).collect::<Vec<f64>>();
        d.set_item("final_position", col(|m| m.final_position).into_pyarray(py))?;
        d.set_item("step_per_cycle", col(|m| m.step_per_cycle).into_pyarray(py))?;
        d.set_item("peak_velocity", col(|m| m.peak_velocity).into_pyarray(py))?;
        d.set_item("peak_friction", col(|m| m.peak_friction).into_pyarray(py))?;
        d.set_item("slip_fraction", col(|m| m.slip_fraction).into_pyarray(py))?;
        d.set_item("diverged_at", col(|m| m.diverged_at).into_pyarray(py))?;
        d.set_item("dt_used", col(|m| m.dt_used).into_pyarray(py))?;
        d.set_item(
            "steps",
            metrics
                .iter()
                .map(|m| m.steps)
                .collect::<Vec<u64>>()
                .into_pyarray(py),
        )?;
        d.set_item(
            "status",
            metrics
                .iter()
                .map(|m| m.status as u8)
                .collect::<Vec<u8>>()
                .into_pyarray(py),
        )?;
        Ok(d)
    }
}

/// Start a batch. `params`: (P, 23) in `param_names()` order, NaN normal_force = derived;
/// `effects`: (P, 9) in `effect_names()` order; `waves`: (P, 8) in `WAVE_COLUMNS` order.
#[pyfunction]
#[pyo3(signature = (params, effects, waves, sampled_t, sampled_v, model, n_elements, piezo_hysteresis, t_end, dt, method, rtol, atol, retries, threads, t_ends=None, record_every=0))]
#[allow(clippy::too_many_arguments)]
fn start_batch(
    params: PyReadonlyArray2<'_, f64>,
    effects: PyReadonlyArray2<'_, f64>,
    waves: PyReadonlyArray2<'_, f64>,
    sampled_t: Option<Vec<f64>>,
    sampled_v: Option<Vec<f64>>,
    model: &str,
    n_elements: usize,
    piezo_hysteresis: bool,
    t_end: f64,
    dt: f64,
    method: &str,
    rtol: f64,
    atol: f64,
    retries: u32,
    threads: usize,
    t_ends: Option<Vec<f64>>,
    record_every: usize,
) -> PyResult<BatchRun> {
    let n = params.shape()[0];
    let shape_ok = |a: &[usize], cols: usize| a == [n, cols];
    if !shape_ok(params.shape(), PARAM_NAMES.len())
        || !shape_ok(effects.shape(), EFFECT_NAMES.len())
        || !shape_ok(waves.shape(), WAVE_COLUMNS.len())
    {
        return Err(value_error(format!(
            "batch arrays must be ({n}, {}), ({n}, {}), ({n}, {}); got {:?}, {:?}, {:?}",
            PARAM_NAMES.len(),
            EFFECT_NAMES.len(),
            WAVE_COLUMNS.len(),
            params.shape(),
            effects.shape(),
            waves.shape()
        )));
    }
    let method = match method {
        "rk4" => Method::Rk4,
        "dopri5" => Method::Dopri5 { rtol, atol },
        other => {
            return Err(value_error(format!(
                "parameter 'method' must be 'rk4' or 'dopri5', got '{other}'"
            )))
        }
    };
    if t_ends.as_ref().is_some_and(|t| t.len() != n) {
        return Err(value_error(format!(
            "'t_ends' must have one duration per point ({n})"
        )));
    }
    let cfg = BatchConfig {
        structure: parse_structure(model, n_elements)?,
        piezo_hysteresis,
        t_end,
        dt,
        method,
        retries,
        record_every,
    };
    let sampled = match (sampled_t, sampled_v) {
        (Some(t), Some(v)) => Some((t, v)),
        _ => None,
    };
    // copies: the worker thread must not touch Python memory
    let pm: Vec<f64> = params.as_array().iter().copied().collect();
    let em: Vec<f64> = effects.as_array().iter().copied().collect();
    let wm: Vec<f64> = waves.as_array().iter().copied().collect();
    let (cancel, done) = (
        Arc::new(AtomicBool::new(false)),
        Arc::new(AtomicUsize::new(0)),
    );
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(threads)
        .build()
        .map_err(|e| PyRuntimeError::new_err(format!("cannot start worker threads: {e}")))?;
    let (c2, d2) = (cancel.clone(), done.clone());
    let handle = std::thread::spawn(move || -> BatchOutcome {
        let (np, ne, nw) = (PARAM_NAMES.len(), EFFECT_NAMES.len(), WAVE_COLUMNS.len());
        // a point whose values are invalid (a negative mass from a sweep axis, say) is flagged
        // Status::Invalid; it does not stop the others
        let mut specs = Vec::with_capacity(n);
        let mut slot: Vec<Option<usize>> = Vec::with_capacity(n);
        for i in 0..n {
            let prow = &pm[i * np..(i + 1) * np];
            let pairs: Vec<(&str, f64)> = PARAM_NAMES
                .iter()
                .copied()
                .zip(prow.iter().copied())
                .filter(|(name, v)| !(*name == "normal_force" && v.is_nan()))
                .collect();
            let erow = &em[i * ne..(i + 1) * ne];
            let epairs: Vec<(&str, f64)> = EFFECT_NAMES
                .iter()
                .copied()
                .zip(erow.iter().copied())
                .collect();
            let spec = Params::from_pairs(&pairs)
                .and_then(|p| Ok((p, Effects::from_pairs(&epairs)?)))
                .and_then(|(p, e)| Ok((p, e, point_wave(&wm[i * nw..(i + 1) * nw], &sampled)?)));
            match spec {
                Ok((params, effects, (wave, cycles))) => {
                    let t_end = t_ends.as_ref().map(|t| t[i]);
                    slot.push(Some(specs.len()));
                    specs.push(PointSpec {
                        params,
                        effects,
                        wave,
                        cycles,
                        t_end,
                    });
                }
                Err(_) => {
                    slot.push(None);
                    d2.fetch_add(1, Ordering::Relaxed);
                }
            }
        }
        let run = || {
            catch_unwind(AssertUnwindSafe(|| {
                pool.install(|| run_batch(&cfg, &specs, &c2, &d2))
            }))
        };
        let mut results = match run() {
            Ok(r) => r.map_err(|e| e.to_string())?,
            Err(_) => return Err("internal error in idm-rs batch (please report)".into()),
        };
        let invalid = PointOutput {
            metrics: PointMetrics {
                status: Status::Invalid,
                ..PointMetrics::not_run()
            },
            trace: Vec::new(),
        };
        Ok(slot
            .into_iter()
            .map(|s| {
                s.map_or_else(
                    || invalid.clone(),
                    |k| std::mem::replace(&mut results[k], invalid.clone()),
                )
            })
            .collect())
    });
    Ok(BatchRun {
        cancel,
        done,
        total: n,
        handle: Mutex::new(Some(handle)),
    })
}

/// Raise ValueError if a run with these settings would be refused (step, duration, model).
#[pyfunction]
#[pyo3(signature = (params, effects, wave_t, wave_v, t_end, dt, model, n_elements, method))]
#[allow(clippy::too_many_arguments)]
fn check_plan(
    params: HashMap<String, f64>,
    effects: HashMap<String, f64>,
    wave_t: Vec<f64>,
    wave_v: Vec<f64>,
    t_end: f64,
    dt: f64,
    model: &str,
    n_elements: usize,
    method: &str,
) -> PyResult<()> {
    let m = Model::new(
        parse_params(&params)?,
        parse_effects(&effects)?,
        parse_structure(model, n_elements)?,
        false,
        false,
    )
    .map_err(value_error)?;
    let wave = PiecewiseLinear::new(wave_t, wave_v).map_err(value_error)?;
    if method == "rk4" {
        plan_steps(&m, &wave, t_end, dt).map_err(|e| value_error(e.to_string()))?;
    } else if !(t_end.is_finite() && t_end > 0.0 && dt.is_finite() && dt > 0.0) {
        return Err(value_error(format!(
            "'t_end' and 'dt' must be positive and finite, got {t_end}, {dt}"
        )));
    }
    Ok(())
}

#[pyfunction]
fn wave_columns() -> Vec<&'static str> {
    WAVE_COLUMNS.to_vec()
}

#[pymodule]
fn _core(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_class::<BatchRun>()?;
    m.add_function(wrap_pyfunction!(start_batch, m)?)?;
    m.add_function(wrap_pyfunction!(wave_columns, m)?)?;
    m.add_function(wrap_pyfunction!(check_plan, m)?)?;
    m.add("DivergenceError", m.py().get_type::<DivergenceError>())?;
    m.add_function(wrap_pyfunction!(simulate, m)?)?;
    m.add_function(wrap_pyfunction!(resolve_params, m)?)?;
    m.add_function(wrap_pyfunction!(param_names, m)?)?;
    m.add_function(wrap_pyfunction!(effect_names, m)?)?;
    m.add_function(wrap_pyfunction!(highest_frequency, m)?)?;
    m.add("__version__", env!("CARGO_PKG_VERSION"))?;
    declarations::register(m)?;
    Ok(())
}

// ==== declarations: Table 1, the effect catalogue, gravity ===================================
// Read-only descriptions of the model for the Python side (units, bounds, catalogue text); kept
// in one block apart from the engine's entry points above, registered by
// `register_declarations`.

mod declarations {
    use pyo3::prelude::*;
    use pyo3::types::PyDict;

    use crate::declare::ParamDecl;
    use crate::effects::EFFECTS;
    use crate::params::{GRAVITY, TABLE1};

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

    pub(super) fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
        m.add_function(wrap_pyfunction!(param_declarations, m)?)?;
        m.add_function(wrap_pyfunction!(effect_declarations, m)?)?;
        // standard gravity [m/s^2] of the default normal force
        m.add("GRAVITY", GRAVITY)?;
        Ok(())
    }
}
// ==== end of declarations ====================================================================
