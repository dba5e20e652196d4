//! A batch of points from Python: started on a background thread, polled for progress,
//! cancelled, its tables and metric columns handed over as numpy arrays (`batch::runner`).

use super::*;

/// A batch running on a background thread (see `batch::runner`).
#[pyclass(module = "idm_rs._core")]
struct BatchRun {
    runner: BatchRunner,
    final_states: bool,
    /// names whose derivatives each point returns
    sensitivities: Vec<String>,
}

#[pymethods]
impl BatchRun {
    /// Points finished so far.
    fn progress(&self) -> usize {
        self.runner.progress()
    }

    #[getter]
    fn total(&self) -> usize {
        self.runner.total()
    }

    /// Ask the workers to stop; points already finished are kept.
    fn cancel(&self) {
        self.runner.cancel();
    }

    /// Wait up to `timeout` seconds (GIL released); True when the batch has finished.
    fn wait(&self, py: Python<'_>, timeout: f64) -> bool {
        py.detach(|| self.runner.wait(timeout))
    }

    /// Join and return the metrics as a dict of arrays (NaN / status 0 for points not run),
    /// with `traces` (a list of arrays) when readings were recorded and `final_states` (a list
    /// of arrays, empty where a point did not finish) when asked for.
    fn result<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        let outputs = py.detach(|| self.runner.join()).map_err(|e| {
            if e.contains("already taken") {
                PyRuntimeError::new_err(String::from(e))
            } else {
                value_error(e)
            }
        })?;
        let d = PyDict::new(py);
        if outputs.iter().any(|o| !o.trace.is_empty()) {
            let traces = PyList::empty(py);
            for o in &outputs {
                traces.append(PyArray1::from_slice(py, &o.trace))?;
            }
            d.set_item("traces", traces)?;
        }
        if self.final_states {
            // one array per point (its layout's size; empty where the point did not finish)
            let states = PyList::empty(py);
            for o in &outputs {
                states.append(PyArray1::from_slice(py, &o.final_state))?;
            }
            d.set_item("final_states", states)?;
        }
        if !self.sensitivities.is_empty() {
            // one (names x samples) array per point; empty where the point did not finish
            let n = self.sensitivities.len();
            let sens = PyList::empty(py);
            for o in &outputs {
                let samples = o.sensitivities.len() / n;
                sens.append(PyArray1::from_slice(py, &o.sensitivities).reshape([n, samples])?)?;
            }
            d.set_item("sensitivities", sens)?;
            d.set_item("sensitivity_names", self.sensitivities.clone())?;
        }
        let reasons = PyList::empty(py);
        for o in &outputs {
            reasons.append(&o.reason)?;
        }
        d.set_item("reasons", reasons)?;
        let metrics: Vec<PointMetrics> = outputs.into_iter().map(|o| o.metrics).collect();
        let col = |f: fn(&PointMetrics) -> f64| metrics.iter().map(f).collect::<Vec<f64>>();
        for (name, _, _, value) in METRIC_COLUMNS {
            d.set_item(name, col(value).into_pyarray(py))?;
        }
        d.set_item("diverged_at", col(|m| m.diverged_at).into_pyarray(py))?;
        d.set_item("dt_used", col(|m| m.dt_used).into_pyarray(py))?;
        let steps: Vec<u64> = metrics.iter().map(|m| m.steps).collect();
        d.set_item("steps", steps.into_pyarray(py))?;
        let status: Vec<u8> = metrics.iter().map(|m| m.status as u8).collect();
        d.set_item("status", status.into_pyarray(py))?;
        Ok(d)
    }
}

/// Start a batch. One row per point: `params` (P, 24) in `param_names()` order (NaN
/// normal_force = derived), `effects` (P, 9) in `effect_names()` order, `wave_fields` (P, k) in
/// `wave_fields(wave_kind)` order; optional per-point `t_ends`, `t_starts` [s] and
/// `initial_states` (P, state size).
#[pyfunction]
#[pyo3(signature = (config, t_end, params, effects, wave_kind, wave_fields, sampled=None, t_ends=None, t_starts=None, initial_states=None, sensitivities=None, derivatives_only=false))]
#[allow(clippy::too_many_arguments)]
fn start_batch(
    py: Python<'_>,
    config: &RunConfig,
    t_end: f64,
    params: PyReadonlyArray2<'_, f64>,
    effects: PyReadonlyArray2<'_, f64>,
    wave_kind: &str,
    wave_fields: PyReadonlyArray2<'_, f64>,
    sampled: Option<(PyReadonlyArray1<'_, f64>, PyReadonlyArray1<'_, f64>)>,
    t_ends: Option<PyReadonlyArray1<'_, f64>>,
    t_starts: Option<PyReadonlyArray1<'_, f64>>,
    initial_states: Option<PyReadonlyArray2<'_, f64>>,
    sensitivities: Option<Vec<String>>,
    derivatives_only: bool,
) -> PyResult<BatchRun> {
    let samples = sampled
        .as_ref()
        .map(|(t, v)| (slice1(t).into_owned(), slice1(v).into_owned()));
    let family = WaveFamily::new(wave_kind, samples).map_err(value_error)?;
    let cfg = BatchConfig {
        structure: config.structure()?,
        piezo_hysteresis: config.piezo_hysteresis,
        t_end,
        method: config.method()?,
        retries: config.retries,
        record_every: config.record_every,
        final_states: config.final_states,
        skip_cycles: config.skip_cycles,
        sensitivities: sensitivities.unwrap_or_default(),
        derivatives_only,
    };
    let (p, e, w) = (slice2(&params), slice2(&effects), slice2(&wave_fields));
    let (te, ts) = (t_ends.as_ref().map(slice1), t_starts.as_ref().map(slice1));
    let st = initial_states.as_ref().map(|a| (slice2(a), a.shape()[1]));
    let tables = PointTables {
        params: &p,
        effects: &e,
        waves: &w,
        family: &family,
        t_ends: te.as_deref(),
        t_starts: ts.as_deref(),
        states: st.as_ref().map(|(s, d)| (&s[..], *d)),
    };
    let points = detached(py, || tables.points())?.map_err(value_error)?;
    let cfg_names = cfg.sensitivities.clone();
    let runner = BatchRunner::start(cfg, points, config.threads).map_err(value_error)?;
    Ok(BatchRun {
        runner,
        final_states: config.final_states,
        sensitivities: cfg_names,
    })
}

pub(super) fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_class::<BatchRun>()?;
    m.add_function(wrap_pyfunction!(start_batch, m)?)?;
    Ok(())
}
