//! Python bindings of hilcontact-core (`hilcontact._core`): convert types, map errors,
//! release the GIL. No numerics here.

use hilcontact_core::{CoreError, Scenario, Table};
use numpy::IntoPyArray;
use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;
use pyo3::types::{PyDict, PyType};

/// `hilcontact.errors.ScenarioError` (a `ValueError`) carrying `message`; a plain
/// `ValueError` if the package's error module cannot be imported.
fn scenario_error(py: Python<'_>, message: String) -> PyErr {
    let class = PyModule::import(py, "hilcontact.errors")
        .and_then(|m| m.getattr("ScenarioError"))
        .and_then(|c| c.downcast_into::<PyType>().map_err(PyErr::from));
    match class {
        Ok(class) => PyErr::from_type(class, message),
        Err(_) => PyValueError::new_err(message),
    }
}

/// The one conversion from core errors to Python exceptions.
fn to_py_err(py: Python<'_>, error: CoreError) -> PyErr {
    match error {
        CoreError::InvalidScenario { .. } => scenario_error(py, error.to_string()),
    }
}

fn table_to_dict<'py>(py: Python<'py>, table: Table) -> PyResult<Bound<'py, PyDict>> {
    let dict = PyDict::new(py);
    for (name, values) in table.columns {
        dict.set_item(name, values.into_pyarray(py))?;
    }
    Ok(dict)
}

/// Runs a scenario (its fully resolved form as JSON): the ideal reference and the HIL loop.
/// Returns `{"timeseries": {column: ndarray}, "reference": {column: ndarray}, "metrics": str}`.
#[pyfunction]
fn simulate<'py>(py: Python<'py>, scenario_json: &str) -> PyResult<Bound<'py, PyDict>> {
    let scenario: Scenario = serde_json::from_str(scenario_json)
        .map_err(|e| scenario_error(py, format!("scenario: {e}")))?;
    let output = py
        .allow_threads(|| hilcontact_core::simulate(&scenario))
        .map_err(|e| to_py_err(py, e))?;
    let metrics =
        serde_json::to_string(&output.metrics).map_err(|e| PyValueError::new_err(e.to_string()))?;
    let result = PyDict::new(py);
    result.set_item("timeseries", table_to_dict(py, output.timeseries)?)?;
    result.set_item("reference", table_to_dict(py, output.reference)?)?;
    result.set_item("metrics", metrics)?;
    Ok(result)
}

fn parse_scenario(py: Python<'_>, json: &str) -> PyResult<Scenario> {
    serde_json::from_str(json).map_err(|e| scenario_error(py, format!("scenario: {e}")))
}

/// Runs many scenarios (each its resolved form as JSON) in parallel on Rust threads, the GIL
/// released, keeping only each run's summary (no time series). `threads`: size of the thread
/// pool (default: rayon's global pool, one thread per core).
///
/// Returns columns, one value per scenario in the given order: `status` (list of "ok" /
/// "diverged"), and arrays `diverged_at` (s, NaN if ok), `collisions`, `reference_collisions`,
/// `mean_cov`, `worst_cov`, `mean_cof`, `worst_cof`, `stiffness_error` (fraction),
/// `damping_error` (N·s/m), `energy_ratio` (final energy / the reference's), `wall_time` (s)
/// (NaN where a run has no such value).
#[pyfunction]
#[pyo3(signature = (scenarios, threads=None))]
fn simulate_batch<'py>(
    py: Python<'py>,
    scenarios: Vec<String>,
    threads: Option<usize>,
) -> PyResult<Bound<'py, PyDict>> {
    use rayon::prelude::*;
    let parsed = scenarios
        .iter()
        .map(|json| parse_scenario(py, json))
        .collect::<PyResult<Vec<_>>>()?;
    let run_all = || {
        parsed
            .par_iter()
            .map(|s| {
                let start = std::time::Instant::now();
                let metrics = hilcontact_core::simulate_metrics(s);
                (metrics, start.elapsed().as_secs_f64())
            })
            .collect::<Vec<_>>()
    };
    let results = py.allow_threads(|| -> PyResult<_> {
        match threads {
            None => Ok(run_all()),
            Some(n) => rayon::ThreadPoolBuilder::new()
                .num_threads(n.max(1))
                .build()
                .map(|pool| pool.install(run_all))
                .map_err(|e| PyValueError::new_err(format!("thread pool: {e}"))),
        }
    })?;
    let n = results.len();
    let mut status = Vec::with_capacity(n);
    let mut columns: Vec<(&str, Vec<f64>)> = [
        "diverged_at",
        "collisions",
        "reference_collisions",
        "mean_cov",
        "worst_cov",
        "mean_cof",
        "worst_cof",
        "stiffness_error",
        "damping_error",
        "energy_ratio",
        "wall_time",
    ]
    .iter()
    .map(|name| (*name, Vec::with_capacity(n)))
    .collect();
    for (metrics, wall_time) in results {
        let m = metrics.map_err(|e| to_py_err(py, e))?;
        status.push(
            serde_json::to_value(m.status)
                .map_err(|e| PyValueError::new_err(e.to_string()))?
                .as_str()
                .unwrap_or("")
                .to_string(),
        );
        let id = m.identification.as_ref();
        let values = [
            m.diverged_at.unwrap_or(f64::NAN),
            m.summary.collisions as f64,
            m.reference_collisions.len() as f64,
            m.summary.mean_cov,
            m.summary.worst_cov,
            m.summary.mean_cof,
            m.summary.worst_cof,
            id.map_or(f64::NAN, |i| i.stiffness_error),
            id.map_or(f64::NAN, |i| i.damping_error),
            m.energy.r#final / m.energy.reference_final,
            wall_time,
        ];
        for ((_, column), value) in columns.iter_mut().zip(values) {
            column.push(value);
        }
    }
    let result = PyDict::new(py);
    result.set_item("status", status)?;
    for (name, values) in columns {
        result.set_item(name, values.into_pyarray(py))?;
    }
    Ok(result)
}

/// The core's default parameters of every compensator kind, as JSON
/// (`{"pida": {"kind": "pida", "delay_mode": "align", ...}, ...}`): the Python schema is checked
/// against it so that both layers share one set of defaults.
#[pyfunction]
fn compensator_defaults() -> PyResult<String> {
    use hilcontact_core::compensator::{CompensatorConfig, ModelParams, TdpaParams};
    let kinds = [
        CompensatorConfig::None,
        CompensatorConfig::Pic(ModelParams::default()),
        CompensatorConfig::Dac(ModelParams::default()),
        CompensatorConfig::Pida(ModelParams::default()),
        CompensatorConfig::TdpaImpedance(TdpaParams::default()),
        CompensatorConfig::TdpaAdmittance(TdpaParams::default()),
    ];
    let map: serde_json::Map<String, serde_json::Value> = kinds
        .iter()
        .map(|k| {
            Ok((
                k.kind().to_string(),
                serde_json::to_value(k).map_err(|e| PyValueError::new_err(e.to_string()))?,
            ))
        })
        .collect::<PyResult<_>>()?;
    Ok(serde_json::Value::Object(map).to_string())
}

/// Version of the native core.
#[pyfunction]
fn version() -> &'static str {
    env!("CARGO_PKG_VERSION")
}

#[pymodule]
fn _core(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_function(wrap_pyfunction!(simulate, m)?)?;
    m.add_function(wrap_pyfunction!(simulate_batch, m)?)?;
    m.add_function(wrap_pyfunction!(version, m)?)?;
    m.add_function(wrap_pyfunction!(compensator_defaults, m)?)?;
    Ok(())
}
