//! Thin PyO3 layer: numpy views in (zero copy where contiguous), the pure-Rust core called with
//! the GIL released, numpy arrays out (moved, not copied), errors mapped to Python exceptions.
//! No numerics here: a model's structure is parsed by `Structure::from_name`/`RigDrive::from_name`,
//! a single run (stoppable, with its derivatives) is `simulate::simulate_with_derivatives`, the
//! batch's thread, pool and cancellation live in `batch::runner`, its metric columns are
//! declared in `batch::metrics::METRIC_COLUMNS`. What stays here is what needs the GIL: the
//! Ctrl-C watch of a single run, conversions.

use std::borrow::Cow;
use std::collections::HashMap;
use std::panic::{catch_unwind, AssertUnwindSafe};
use std::sync::atomic::AtomicBool;
use std::time::Duration;

use numpy::{IntoPyArray, PyArray1, PyArrayMethods, PyReadonlyArray1, PyReadonlyArray2, PyUntypedArrayMethods};
use pyo3::create_exception;
use pyo3::exceptions::{PyRuntimeError, PyTypeError, PyValueError};
use pyo3::prelude::*;
use pyo3::types::{PyDict, PyList};

use crate::batch::{BatchConfig, BatchRunner, PointMetrics, PointTables, WaveFamily, METRIC_COLUMNS};
use crate::integrate::method::Method;
use crate::integrate::plan::check_task;
use crate::integrate::task::{SimError, Task};
use crate::model::{Model, N_ACCOUNTING};
use crate::physics::effects::{Effects, EFFECT_NAMES};
use crate::physics::external_force::{Body, ExternalForce};
use crate::physics::mechanics::Structure;
use crate::physics::params::{Params, PARAM_NAMES};
use crate::physics::rig::RigDrive;
use crate::physics::waveform::PiecewiseLinear;
use crate::sensitivity::parse_seeds;
use crate::simulate::simulate_with_derivatives;
use crate::watch::{run_watched, wait_done};

mod batch;
mod declarations;
mod forms;
mod kernel;

create_exception!(
    _core,
    DivergenceError,
    PyRuntimeError,
    "The integration left its physical bounds (a step too large, usually)."
);

fn value_error(msg: impl Into<String>) -> PyErr {
    PyValueError::new_err(msg.into())
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
    py.detach(|| catch_unwind(AssertUnwindSafe(f))).map_err(|p| {
        let what = p
            .downcast_ref::<String>()
            .cloned()
            .or_else(|| p.downcast_ref::<&str>().map(|s| s.to_string()))
            .unwrap_or_else(|| "unknown panic".into());
        PyRuntimeError::new_err(format!("internal error in idm-rs core (please report): {what}"))
    })
}

/// A contiguous view of a 1-D array, or a copy when it is strided.
fn slice1<'a>(a: &'a PyReadonlyArray1<'_, f64>) -> Cow<'a, [f64]> {
    match a.as_slice() {
        Ok(s) => Cow::Borrowed(s),
        Err(_) => Cow::Owned(a.as_array().iter().copied().collect()),
    }
}

/// A row-major view of a 2-D array, or a copy when it is not C-contiguous.
fn slice2<'a>(a: &'a PyReadonlyArray2<'_, f64>) -> Cow<'a, [f64]> {
    match a.as_slice() {
        Ok(s) => Cow::Borrowed(s),
        Err(_) => Cow::Owned(a.as_array().iter().copied().collect()),
    }
}

fn parse_params(params: &HashMap<String, f64>) -> PyResult<Params> {
    let pairs: Vec<(&str, f64)> = params.iter().map(|(k, v)| (k.as_str(), *v)).collect();
    Params::from_pairs(&pairs).map_err(value_error)
}

fn parse_effects(effects: &HashMap<String, f64>) -> PyResult<Effects> {
    let pairs: Vec<(&str, f64)> = effects.iter().map(|(k, v)| (k.as_str(), *v)).collect();
    Effects::from_pairs(&pairs).map_err(value_error)
}

/// Declares [`RunConfig`] from one list of fields — name, type, default, doc — written once:
/// the struct, its defaults, and the keyword parsing of its Python constructor.
macro_rules! run_config {
    ($( $(#[doc = $doc:expr])* $name:ident : $ty:ty = $default:expr ),* $(,)?) => {
        /// How to run: the model's structure and the integration method, shared by `simulate` and
        /// the batch. Built once in Python with keywords; checked on construction.
        #[pyclass(module = "idm_rs._core", frozen, get_all)]
        #[derive(Clone, Debug)]
        struct RunConfig {
            $( $(#[doc = $doc])* $name: $ty, )*
        }

        impl Default for RunConfig {
            fn default() -> Self {
                RunConfig { $( $name: $default, )* }
            }
        }

        impl RunConfig {
            /// Set the fields named in `kwargs`; None keeps a field's default, an unknown keyword
            /// is refused by name.
            fn set_from(&mut self, kwargs: &Bound<'_, PyDict>) -> PyResult<()> {
                for (key, value) in kwargs.iter() {
                    let key: String = key.extract()?;
                    if value.is_none() {
                        continue;
                    }
                    match key.as_str() {
                        $( stringify!($name) => {
                            self.$name = value.extract().map_err(|e| {
                                PyTypeError::new_err(format!("parameter '{}': {e}", stringify!($name)))
                            })?
                        } )*
                        other => {
                            return Err(PyTypeError::new_err(format!(
                                "RunConfig() got an unexpected keyword argument '{other}'"
                            )))
                        }
                    }
                }
                Ok(())
            }
        }
    };
}

run_config! {
    /// "lps", "dps" or "rig"
    model: String = "dps".to_string(),
    /// FEM elements of the DPS bar
    n_elements: usize = 4,
    /// whether the piezo hysteresis state h runs
    piezo_hysteresis: bool = true,
    /// "rk4", "dopri5", "rodas4" or "auto"
    method: String = "rk4".to_string(),
    /// RK4 step [s]
    dt: f64 = 1e-8,
    /// adaptive tolerances (atol in units of each state's scale)
    rtol: f64 = 1e-7,
    atol: f64 = 1e-7,
    /// adaptive first trial step [s] (not given: `dt`)
    first_step: f64 = f64::NAN,
    /// RK4 retries at dt/2, dt/4, ... for a diverging batch point
    retries: u32 = 2,
    /// batch worker threads (below 1: 1)
    threads: usize = 1,
    /// batch: record the sensor reading every this many RK4 steps (0: none)
    record_every: usize = 0,
    /// batch: return each point's final state
    final_states: bool = false,
    /// batch: start-up cycles of a sawtooth train left out of the steady-state metrics
    skip_cycles: usize = 1,
    /// model "rig": "position" (spring to a moving end), "force" (the input is the force) or
    /// "closed_loop" (a position servo)
    rig_drive: String = "position".to_string(),
    /// model "rig", position drive: spring [N/m] and damper [N s/m] to the moving end
    rig_stiffness: f64 = 0.0,
    rig_damping: f64 = 0.0,
    /// model "rig", closed-loop drive: position gain [1/s], velocity gain [V s/m], actuator
    /// constant [N/V] and the controller's saturation [V] (0: none)
    rig_kp: f64 = 0.0,
    rig_kv: f64 = 0.0,
    rig_gain: f64 = 0.0,
    rig_limit: f64 = 0.0,
}

impl RunConfig {
    fn structure(&self) -> PyResult<Structure> {
        Structure::from_name(&self.model, self.n_elements, || {
            RigDrive::from_name(
                &self.rig_drive,
                self.rig_stiffness,
                self.rig_damping,
                self.rig_kp,
                self.rig_kv,
                self.rig_gain,
                self.rig_limit,
            )
        })
        .map_err(value_error)
    }

    fn method(&self) -> PyResult<Method> {
        Method::from_name(&self.method, self.dt, self.rtol, self.atol, self.first_step).map_err(value_error)
    }

    fn model(&self, p: Params, e: Effects, accounting: bool) -> PyResult<Model> {
        Model::new(p, e, self.structure()?, self.piezo_hysteresis, accounting).map_err(value_error)
    }
}

#[pymethods]
impl RunConfig {
    #[new]
    #[pyo3(signature = (**kwargs))]
    fn new(kwargs: Option<&Bound<'_, PyDict>>) -> PyResult<Self> {
        let mut c = RunConfig::default();
        if let Some(k) = kwargs {
            c.set_from(k)?;
        }
        if c.first_step.is_nan() {
            c.first_step = c.dt;
        }
        c.threads = c.threads.max(1);
        c.structure()?;
        c.method()?;
        Ok(c)
    }

    fn __repr__(&self) -> String {
        format!("{self:?}")
    }
}

/// Table 1 overridden by `params`, with the derived normal force filled in.
#[pyfunction]
fn resolve_params(params: HashMap<String, f64>) -> PyResult<HashMap<String, f64>> {
    let p = parse_params(&params)?;
    Ok(PARAM_NAMES.iter().map(|n| (n.to_string(), p.get(n).unwrap())).collect())
}

/// The batch's metric columns: (name, unit, long name), in result order.
#[pyfunction]
fn metric_columns() -> Vec<(&'static str, &'static str, &'static str)> {
    METRIC_COLUMNS.iter().map(|(n, u, l, _)| (*n, *u, *l)).collect()
}

#[pyfunction]
fn param_names() -> Vec<&'static str> {
    PARAM_NAMES.to_vec()
}

#[pyfunction]
fn effect_names() -> Vec<&'static str> {
    EFFECT_NAMES.to_vec()
}

/// The instruction set the lane groups of plain models run on ("scalar", "avx2", "avx512").
#[pyfunction]
fn simd_level() -> &'static str {
    crate::lanes::simd_level()
}

/// Choose the lane groups' instruction set: "scalar", "avx2" (the default) or "avx512" (the
/// best the processor has at or below it). Results are bitwise the same; only speed differs.
#[pyfunction]
fn set_simd_level(level: &str) -> PyResult<()> {
    if !["scalar", "avx2", "avx512"].contains(&level) {
        return Err(PyValueError::new_err(format!(
            "simd level must be 'scalar', 'avx2' or 'avx512', got '{level}'"
        )));
    }
    crate::lanes::set_simd_level(level);
    Ok(())
}

/// Per-point waveform fields of a batch of `kind` ("triangle", "sawtooth", "sampled").
#[pyfunction]
fn wave_fields(kind: &str) -> PyResult<Vec<&'static str>> {
    let fam = WaveFamily::new(kind, Some((vec![0.0], vec![0.0]))).map_err(value_error)?;
    Ok(fam.fields().to_vec())
}

/// Highest structural natural frequency [rad/s] of the model.
#[pyfunction]
fn highest_frequency(params: HashMap<String, f64>, config: &RunConfig) -> PyResult<f64> {
    let m = config.model(parse_params(&params)?, Effects::default(), false)?;
    Ok(m.mech.highest_frequency())
}

/// The largest RK4 step [s] the damped structure of the model allows (the up-front check's
/// limit: every eigenvalue inside RK4's stability region, with its margin).
#[pyfunction]
fn rk4_step_limit(params: HashMap<String, f64>, config: &RunConfig) -> PyResult<f64> {
    let m = config.model(parse_params(&params)?, Effects::default(), false)?;
    Ok(crate::integrate::plan::rk4_structure_limit(&m.mech.eigenvalues()).0)
}

/// Name and unit of every state component of the model (see `Layout::components`).
#[pyfunction]
#[pyo3(signature = (params, effects, config, energy=false))]
fn state_components(
    params: HashMap<String, f64>,
    effects: HashMap<String, f64>,
    config: &RunConfig,
    energy: bool,
) -> PyResult<Vec<(String, &'static str)>> {
    let m = config.model(parse_params(&params)?, parse_effects(&effects)?, energy)?;
    Ok(m.layout.components())
}

/// A sampled external force as Python passes it: (times [s], forces [N], body name).
type ExternalForceArg<'a> = (PyReadonlyArray1<'a, f64>, PyReadonlyArray1<'a, f64>, String);

/// `m` with the sampled external force, if one is given.
fn with_external(m: Model, force: Option<ExternalForceArg<'_>>) -> PyResult<Model> {
    let Some((t, f, body)) = force else { return Ok(m) };
    let body = Body::from_name(&body).map_err(value_error)?;
    let force = ExternalForce::new(body, slice1(&t).into_owned(), slice1(&f).into_owned()).map_err(value_error)?;
    m.with_external_force(force).map_err(value_error)
}

/// Raise ValueError if a run with these settings would be refused (span, step, model, state).
#[pyfunction]
#[pyo3(signature = (params, effects, wave_t, wave_v, t_start, t_end, config, initial_state=None, external_force=None))]
#[allow(clippy::too_many_arguments)]
fn check_run(
    params: HashMap<String, f64>,
    effects: HashMap<String, f64>,
    wave_t: PyReadonlyArray1<'_, f64>,
    wave_v: PyReadonlyArray1<'_, f64>,
    t_start: f64,
    t_end: f64,
    config: &RunConfig,
    initial_state: Option<PyReadonlyArray1<'_, f64>>,
    external_force: Option<ExternalForceArg<'_>>,
) -> PyResult<()> {
    let m = with_external(
        config.model(parse_params(&params)?, parse_effects(&effects)?, false)?,
        external_force,
    )?;
    let wave = PiecewiseLinear::new(slice1(&wave_t).into_owned(), slice1(&wave_v).into_owned()).map_err(value_error)?;
    let y0 = initial_state.as_ref().map(slice1);
    let rest = m.rest_state();
    let task = Task {
        model: &m,
        wave: &wave,
        t_start,
        t_end,
        y0: y0.as_deref().unwrap_or(&rest),
    };
    check_task(&task, &config.method()?).map_err(|e| value_error(e.to_string()))
}

/// `work` run on a worker thread while this one looks for Ctrl-C (Python's signal handlers run
/// only here) and sets `cancel` on it, so the run stops and keeps what it saved so far; a panic
/// in `work` becomes a Python RuntimeError, never a crash. Also returns whether a Ctrl-C came
/// while it ran: each look takes the signal (else Python would raise it the moment this
/// returns, and the finished run would be lost), so a run that ended before it saw `cancel`
/// is whole and the caller says it was interrupted.
fn watching_for_ctrl_c<T: Send>(
    py: Python<'_>,
    cancel: &AtomicBool,
    work: impl FnOnce() -> T + Send,
) -> PyResult<(T, bool)> {
    run_watched(
        cancel,
        work,
        |done| py.detach(|| wait_done(done, Duration::from_millis(50))),
        || py.check_signals().is_err(),
    )
    .ok_or_else(|| PyRuntimeError::new_err("internal error in idm-rs core (please report)"))
}

/// Simulate one run; returns a dict of numpy arrays (see `idm_rs.simulate`). With
/// `sensitivities` (names), also `sensitivities` (saved times x names): d reading / d name,
/// and `final_state_sensitivities` (state components x names).
#[pyfunction]
#[pyo3(signature = (params, effects, wave_t, wave_v, t_start, t_end, config, save_every, energy, initial_state=None, sensitivities=None, external_force=None))]
#[allow(clippy::too_many_arguments)]
fn simulate<'py>(
    py: Python<'py>,
    params: HashMap<String, f64>,
    effects: HashMap<String, f64>,
    wave_t: PyReadonlyArray1<'_, f64>,
    wave_v: PyReadonlyArray1<'_, f64>,
    t_start: f64,
    t_end: f64,
    config: &RunConfig,
    save_every: usize,
    energy: bool,
    initial_state: Option<PyReadonlyArray1<'_, f64>>,
    sensitivities: Option<Vec<String>>,
    external_force: Option<ExternalForceArg<'_>>,
) -> PyResult<Bound<'py, PyDict>> {
    let m = with_external(
        config.model(parse_params(&params)?, parse_effects(&effects)?, energy)?,
        external_force,
    )?;
    let names = sensitivities.unwrap_or_default();
    let normal_force_derived = !params.contains_key("normal_force");
    let seeds = parse_seeds(&m, &names, normal_force_derived).map_err(value_error)?;
    let method = config.method()?;
    let wave = PiecewiseLinear::new(slice1(&wave_t).into_owned(), slice1(&wave_v).into_owned()).map_err(value_error)?;
    let y0: Vec<f64> = match &initial_state {
        Some(a) => slice1(a).into_owned(),
        None => m.rest_state(),
    };
    let cancel = AtomicBool::new(false);
    let (run, late) = watching_for_ctrl_c(py, &cancel, || {
        simulate_with_derivatives(
            &m,
            &wave,
            t_start,
            t_end,
            &y0,
            &method,
            save_every,
            &seeds,
            normal_force_derived,
            &cancel,
        )
    })?;
    let (traj, complete, derived) = run.map_err(|e| sim_error(py, e))?;

    let nt = traj.t.len();
    let dof = traj.dof;
    let d = PyDict::new(py);
    let arr2 = |v: Vec<f64>, cols: usize| -> PyResult<Bound<'py, PyAny>> {
        Ok(v.into_pyarray(py).reshape([nt, cols])?.into_any())
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
    d.set_item("state_components", m.layout.components())?;
    d.set_item("complete", complete)?;
    // a Ctrl-C that came as the run ended: the run is whole, Python raises with it attached
    d.set_item("interrupted", late)?;
    if let Some(s) = derived {
        let n = s.names;
        d.set_item("sensitivity_names", names)?;
        d.set_item("sensitivities", arr2(s.readings, n)?)?;
        let dim = s.final_state.len() / n.max(1);
        d.set_item(
            "final_state_sensitivities",
            s.final_state.into_pyarray(py).reshape([dim, n])?,
        )?;
    }
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
    m.add_class::<RunConfig>()?;
    m.add_function(wrap_pyfunction!(wave_fields, m)?)?;
    m.add_function(wrap_pyfunction!(simd_level, m)?)?;
    m.add_function(wrap_pyfunction!(set_simd_level, m)?)?;
    m.add_function(wrap_pyfunction!(check_run, m)?)?;
    m.add("DivergenceError", m.py().get_type::<DivergenceError>())?;
    m.add_function(wrap_pyfunction!(simulate, m)?)?;
    m.add_function(wrap_pyfunction!(state_components, m)?)?;
    m.add_function(wrap_pyfunction!(resolve_params, m)?)?;
    m.add_function(wrap_pyfunction!(param_names, m)?)?;
    m.add_function(wrap_pyfunction!(metric_columns, m)?)?;
    m.add_function(wrap_pyfunction!(effect_names, m)?)?;
    m.add_function(wrap_pyfunction!(highest_frequency, m)?)?;
    m.add_function(wrap_pyfunction!(rk4_step_limit, m)?)?;
    m.add("__version__", env!("CARGO_PKG_VERSION"))?;
    declarations::register(m)?;
    forms::register(m)?;
    kernel::register(m)?;
    batch::register(m)?;
    Ok(())
}
