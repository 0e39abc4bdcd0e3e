//! Python bindings of hilcontact-core (`hilcontact._core`): convert types, map errors,
//! release the GIL. No numerics here.

use std::time::Duration;

use hilcontact_core::{CoreError, Scenario, Table};
use hilcontact_rt::{EmulatorOptions, FacilityHandle, HilHandle, RtError, RuntimeOptions};
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

/// An exception class of `hilcontact.errors` by name, carrying `message`; `fallback` if the
/// package's error module cannot be imported.
fn package_error(
    py: Python<'_>,
    name: &str,
    message: String,
    fallback: fn(String) -> PyErr,
) -> PyErr {
    let class = PyModule::import(py, "hilcontact.errors")
        .and_then(|m| m.getattr(name))
        .and_then(|c| c.downcast_into::<PyType>().map_err(PyErr::from));
    match class {
        Ok(class) => PyErr::from_type(class, message),
        Err(_) => fallback(message),
    }
}

/// The one conversion from real-time errors to Python exceptions: scenario errors are
/// `ScenarioError`, option errors `RealtimeOptionError` (a `ValueError`), the others
/// (sockets, protocol, connection) `RealtimeError`.
fn rt_err(py: Python<'_>, error: RtError) -> PyErr {
    match error {
        RtError::Scenario(e) => to_py_err(py, e),
        RtError::Option { .. } => package_error(
            py,
            "RealtimeOptionError",
            error.to_string(),
            PyValueError::new_err,
        ),
        _ => package_error(
            py,
            "RealtimeError",
            error.to_string(),
            pyo3::exceptions::PyRuntimeError::new_err,
        ),
    }
}

fn parse_scenario(py: Python<'_>, scenario_json: &str) -> PyResult<Scenario> {
    serde_json::from_str(scenario_json).map_err(|e| scenario_error(py, format!("scenario: {e}")))
}

fn parse_options<T: serde::de::DeserializeOwned>(
    py: Python<'_>,
    options_json: &str,
) -> PyResult<T> {
    serde_json::from_str(options_json).map_err(|e| {
        package_error(
            py,
            "RealtimeOptionError",
            format!("options: {e}"),
            PyValueError::new_err,
        )
    })
}

/// JSON text to a Python object (through the json module: the values are plain data).
fn json_to_py<'py>(py: Python<'py>, value: &impl serde::Serialize) -> PyResult<Bound<'py, PyAny>> {
    let text = serde_json::to_string(value).map_err(|e| PyValueError::new_err(e.to_string()))?;
    PyModule::import(py, "json")?
        .getattr("loads")?
        .call1((text,))
}

/// A running real-time HIL loop (`start_hil`). The loop runs in Rust threads; every method
/// returns at once except `wait` and `finish`, which release the GIL.
#[pyclass(module = "hilcontact._core", name = "HilHandle")]
struct PyHilHandle {
    inner: Option<HilHandle>,
}

impl PyHilHandle {
    fn handle(&self) -> PyResult<&HilHandle> {
        self.inner
            .as_ref()
            .ok_or_else(|| PyValueError::new_err("the run has been finished already"))
    }
}

#[pymethods]
impl PyHilHandle {
    /// A snapshot for the live line: phase, tick, time (s), force (N), energy (J),
    /// max_latency_us, overruns, sensor_lost, sensor_late, robot_lost, robot_late, dropped, stop.
    fn status<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyAny>> {
        json_to_py(py, &self.handle()?.status())
    }

    /// Asks the loop to stop: it commands the robot to hold, stops streaming and flushes.
    fn stop(&self) -> PyResult<()> {
        self.handle()?.stop();
        Ok(())
    }

    /// Whether the loop has ended.
    fn is_finished(&self) -> PyResult<bool> {
        Ok(self.handle()?.is_finished())
    }

    /// Waits up to `timeout` seconds (GIL released); returns whether the loop has ended.
    fn wait(&self, py: Python<'_>, timeout: f64) -> PyResult<bool> {
        let handle = self.handle()?;
        let timeout = Duration::from_secs_f64(timeout.max(0.0));
        Ok(py.allow_threads(|| handle.wait(timeout)))
    }

    /// Waits for the loop and its writer (GIL released) and returns
    /// `{"timeseries": {column: ndarray}, "reference": {...}, "metrics": str, "exit_code": int}`.
    fn finish<'py>(&mut self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        let handle = self
            .inner
            .take()
            .ok_or_else(|| PyValueError::new_err("the run has been finished already"))?;
        let output = py
            .allow_threads(move || handle.finish())
            .map_err(|e| rt_err(py, e))?;
        let result = PyDict::new(py);
        result.set_item("timeseries", table_to_dict(py, output.timeseries)?)?;
        result.set_item("reference", table_to_dict(py, output.reference)?)?;
        result.set_item("metrics", output.metrics.to_string())?;
        result.set_item("exit_code", output.exit_code)?;
        Ok(result)
    }
}

/// Starts the real-time HIL loop of a scenario (JSON) with runtime options (JSON, keys of
/// `RuntimeOptions`: `sensor` and `robot` grouped with their `kind`, defaults for the missing
/// ones). Binds the sockets and reads the sensor's
/// counts per unit before returning; raises RealtimeError if that fails.
#[pyfunction]
fn start_hil(py: Python<'_>, scenario_json: &str, options_json: &str) -> PyResult<PyHilHandle> {
    let scenario = parse_scenario(py, scenario_json)?;
    let options: RuntimeOptions = parse_options(py, options_json)?;
    let handle = py
        .allow_threads(|| HilHandle::start(&scenario, &options))
        .map_err(|e| rt_err(py, e))?;
    Ok(PyHilHandle {
        inner: Some(handle),
    })
}

/// A running emulated facility (`start_facility`).
#[pyclass(module = "hilcontact._core", name = "FacilityHandle")]
struct PyFacilityHandle {
    inner: Option<FacilityHandle>,
}

impl PyFacilityHandle {
    fn handle(&self) -> PyResult<&FacilityHandle> {
        self.inner
            .as_ref()
            .ok_or_else(|| PyValueError::new_err("the facility has been joined already"))
    }
}

#[pymethods]
impl PyFacilityHandle {
    /// Counters: finished, tick, time (s), contact_force (N), rdt_sent, rdt_requests,
    /// rdt_bad_requests, egm_sent, corrections, corrections_dropped, overruns, max_latency_us.
    fn status<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyAny>> {
        json_to_py(py, &self.handle()?.status())
    }

    /// `{"sensor": "host:port", "http": "host:port" | None, "robot": ..., "egm_peer": ...}`.
    fn addresses<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        let a = self.handle()?.addresses();
        let d = PyDict::new(py);
        d.set_item("sensor", a.sensor.to_string())?;
        d.set_item("http", a.http.map(|h| h.to_string()))?;
        d.set_item("robot", a.robot.to_string())?;
        d.set_item("egm_peer", a.egm_peer.to_string())?;
        Ok(d)
    }

    /// Asks the emulator to stop; returns at once.
    fn stop(&self) -> PyResult<()> {
        self.handle()?.stop();
        Ok(())
    }

    /// Whether the emulator has ended.
    fn is_finished(&self) -> PyResult<bool> {
        Ok(self.handle()?.is_finished())
    }

    /// Stops the emulator, waits for it (GIL released) and returns its final counters.
    fn join<'py>(&mut self, py: Python<'py>) -> PyResult<Bound<'py, PyAny>> {
        let handle = self
            .inner
            .take()
            .ok_or_else(|| PyValueError::new_err("the facility has been joined already"))?;
        let status = py.allow_threads(move || handle.join());
        json_to_py(py, &status)
    }
}

/// Starts the emulated facility of a scenario (JSON) with options (JSON, keys of
/// `EmulatorOptions`). Raises RealtimeError if a port cannot be bound.
#[pyfunction]
fn start_facility(
    py: Python<'_>,
    scenario_json: &str,
    options_json: &str,
) -> PyResult<PyFacilityHandle> {
    let scenario = parse_scenario(py, scenario_json)?;
    let options: EmulatorOptions = parse_options(py, options_json)?;
    let handle = py
        .allow_threads(|| FacilityHandle::start(&scenario, &options))
        .map_err(|e| rt_err(py, e))?;
    Ok(PyFacilityHandle {
        inner: Some(handle),
    })
}

/// The default options of the runtime and the emulator, and the device protocols, as JSON:
/// `{"runtime": {...}, "facility": {...}, "protocols": {"sensor": [...], "robot": [...]}}`
/// (the one place the defaults and the protocol lists live).
#[pyfunction]
fn realtime_defaults() -> PyResult<String> {
    let value = serde_json::json!({
        "runtime": RuntimeOptions::default(),
        "facility": EmulatorOptions::default(),
        "protocols": {
            "sensor": hilcontact_rt::links::SENSOR_KINDS,
            "robot": hilcontact_rt::links::ROBOT_KINDS,
        },
    });
    Ok(value.to_string())
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
    let scenario = parse_scenario(py, scenario_json)?;
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
    m.add_function(wrap_pyfunction!(start_hil, m)?)?;
    m.add_function(wrap_pyfunction!(start_facility, m)?)?;
    m.add_function(wrap_pyfunction!(realtime_defaults, m)?)?;
    m.add_class::<PyHilHandle>()?;
    m.add_class::<PyFacilityHandle>()?;
    Ok(())
}
