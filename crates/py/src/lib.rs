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
    m.add_function(wrap_pyfunction!(version, m)?)?;
    m.add_function(wrap_pyfunction!(compensator_defaults, m)?)?;
    Ok(())
}
