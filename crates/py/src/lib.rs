//! Python bindings of hilcontact-core (`hilcontact._core`): convert types, map errors,
//! release the GIL. No numerics here.

use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::mpsc::{sync_channel, RecvTimeoutError};
use std::sync::Arc;
use std::time::Duration;

use hilcontact_core::{CoreError, Plan, Scenario, Table};
use hilcontact_rt::output::{Outputs, RunInfo, OUTPUTS};
use hilcontact_rt::{EmulatorOptions, FacilityHandle, HilHandle, RtError, RuntimeOptions};
use numpy::IntoPyArray;
use pyo3::exceptions::{PyException, PyImportError, PyKeyboardInterrupt, PyOSError, PyValueError};
use pyo3::panic::PanicException;
use pyo3::prelude::*;
use pyo3::sync::GILOnceCell;
use pyo3::types::{PyDict, PyTuple, PyType};

mod calibrate;
mod facility;
mod mesh;
mod plugin;

/// The package's exception classes, defined here once (`hilcontact.errors` re-exports them):
/// `HilContactError(Exception)`, `ScenarioError(HilContactError, ValueError)`,
/// `RealtimeError(HilContactError, OSError)` and `RealtimeOptionError(RealtimeError,
/// ValueError)`.
struct ErrorClasses {
    base: Py<PyType>,
    scenario: Py<PyType>,
    realtime: Py<PyType>,
    option: Py<PyType>,
}

static ERRORS: GILOnceCell<ErrorClasses> = GILOnceCell::new();

/// A new exception class `hilcontact.errors.<name>` with the given bases.
fn exception_class(
    py: Python<'_>,
    name: &str,
    bases: &[&Bound<'_, PyType>],
    doc: &str,
) -> PyResult<Py<PyType>> {
    let namespace = PyDict::new(py);
    namespace.set_item("__module__", "hilcontact.errors")?;
    namespace.set_item("__doc__", doc)?;
    let bases = PyTuple::new(py, bases)?;
    let class = PyModule::import(py, "builtins")?
        .getattr("type")?
        .call1((name, bases, namespace))?;
    Ok(class.downcast_into::<PyType>()?.unbind())
}

fn error_classes(py: Python<'_>) -> PyResult<&ErrorClasses> {
    ERRORS.get_or_try_init(py, || {
        let base = exception_class(
            py,
            "HilContactError",
            &[&py.get_type::<PyException>()],
            "Base class of every error raised on purpose by hilcontact.",
        )?;
        let scenario = exception_class(
            py,
            "ScenarioError",
            &[base.bind(py), &py.get_type::<PyValueError>()],
            "A scenario (file, preset name, override or value) is invalid. The message is one \
             line naming the first offending key as a dotted path and what is allowed; \
             `issues` lists every problem as (key, message).",
        )?;
        let realtime = exception_class(
            py,
            "RealtimeError",
            &[base.bind(py), &py.get_type::<PyOSError>()],
            "The real-time runtime or the emulated facility could not start or finish: a port \
             in use, a peer that does not answer, a bad /netftapi2.xml. Also an OSError: for an \
             error of the OS, `errno` (e.g. errno.EADDRINUSE) and `strerror` are set and `kind` \
             names the Rust std::io::ErrorKind (e.g. 'AddrInUse'); otherwise `errno` is None.",
        )?;
        let option = exception_class(
            py,
            "RealtimeOptionError",
            &[realtime.bind(py), &py.get_type::<PyValueError>()],
            "A real-time option (limit, port, mapping) is invalid; the message names it.",
        )?;
        Ok(ErrorClasses {
            base,
            scenario,
            realtime,
            option,
        })
    })
}

/// An exception of `class` carrying `message`.
fn raise(py: Python<'_>, class: fn(&ErrorClasses) -> &Py<PyType>, message: String) -> PyErr {
    match error_classes(py) {
        Ok(classes) => PyErr::from_type(class(classes).bind(py).clone(), message),
        Err(e) => e,
    }
}

/// A `RealtimeError` from the OS: constructed with `(errno, strerror)` as `OSError` is, so
/// `exc.errno` and `exc.strerror` are set (and `str(exc)` is `[Errno N] strerror`); `kind` is
/// the Rust `std::io::ErrorKind` (e.g. `"AddrInUse"`).
fn raise_os(py: Python<'_>, errno: i32, kind: std::io::ErrorKind, strerror: String) -> PyErr {
    match error_classes(py) {
        Ok(classes) => {
            let err = PyErr::from_type(classes.realtime.bind(py).clone(), (errno, strerror));
            // best effort: the errno and the message are set already
            let _ = err.value(py).setattr("kind", format!("{kind:?}"));
            err
        }
        Err(e) => e,
    }
}

/// The one conversion from core errors: `ScenarioError`, with every problem in `issues`.
fn to_py_err(py: Python<'_>, error: CoreError) -> PyErr {
    let issues: Vec<(String, String)> = error
        .issues()
        .into_iter()
        .map(|i| (i.key, i.message))
        .collect();
    let err = match error {
        CoreError::InvalidScenario { .. } => raise(py, |c| &c.scenario, error.to_string()),
    };
    // best effort: the message already holds the first problem and the other keys
    let _ = err.value(py).setattr("issues", issues);
    err
}

/// The one conversion from real-time errors (exhaustive: a new variant must be placed here):
/// scenario errors are `ScenarioError`, option errors `RealtimeOptionError`, OS errors
/// `RealtimeError` with `errno`, `strerror` and `kind` set, the others (an I/O error that did
/// not come from the OS, protocol, connection) `RealtimeError` with `errno` None.
fn rt_err(py: Python<'_>, error: RtError) -> PyErr {
    match error {
        RtError::Scenario(e) => to_py_err(py, e),
        RtError::Option { .. } => raise(py, |c| &c.option, error.to_string()),
        RtError::Io {
            errno: Some(errno),
            kind,
            ..
        } => raise_os(py, errno, kind, error.to_string()),
        RtError::Io { errno: None, .. } | RtError::Protocol(_) | RtError::Connect(_) => {
            raise(py, |c| &c.realtime, error.to_string())
        }
    }
}

/// A scenario's JSON, resolved into a plan (every problem reported).
fn parse_scenario(py: Python<'_>, scenario_json: &str) -> PyResult<Plan> {
    let scenario: Scenario = serde_json::from_str(scenario_json)
        .map_err(|e| raise(py, |c| &c.scenario, format!("scenario: {e}")))?;
    scenario.resolve().map_err(|e| to_py_err(py, e))
}

/// A scenario's JSON, as data (the runtime and the emulator resolve it themselves).
fn scenario_data(py: Python<'_>, scenario_json: &str) -> PyResult<Scenario> {
    serde_json::from_str(scenario_json)
        .map_err(|e| raise(py, |c| &c.scenario, format!("scenario: {e}")))
}

fn parse_options<T: serde::de::DeserializeOwned>(
    py: Python<'_>,
    options_json: &str,
) -> PyResult<T> {
    serde_json::from_str(options_json)
        .map_err(|e| raise(py, |c| &c.option, format!("options: {e}")))
}

/// JSON text to a Python object (through the json module: the values are plain data).
fn json_to_py<'py>(py: Python<'py>, value: &impl serde::Serialize) -> PyResult<Bound<'py, PyAny>> {
    let text = serde_json::to_string(value).map_err(|e| PyValueError::new_err(e.to_string()))?;
    PyModule::import(py, "json")?
        .getattr("loads")?
        .call1((text,))
}

/// Parses a scenario and options (JSON) and runs `run` on them with the GIL released; an
/// error becomes the matching Python exception.
fn run_released<O, R>(
    py: Python<'_>,
    scenario_json: &str,
    options_json: &str,
    run: impl FnOnce(&Scenario, &O) -> hilcontact_rt::Result<R> + Send,
) -> PyResult<R>
where
    O: serde::de::DeserializeOwned + Sync,
    R: Send,
{
    let scenario = scenario_data(py, scenario_json)?;
    let options: O = parse_options(py, options_json)?;
    py.allow_threads(|| run(&scenario, &options))
        .map_err(|e| rt_err(py, e))
}

/// How often a long call checks Python's signals (Ctrl-C) while the core works.
const SIGNAL_POLL: Duration = Duration::from_millis(20);

/// Runs `work` on a thread of its own while this thread waits for it with the GIL released,
/// checking Python's signals every [`SIGNAL_POLL`] (`py.check_signals()`): a Ctrl-C (or a
/// SIGTERM that Python turns into KeyboardInterrupt) raises within that time instead of after
/// the whole run. `work` gets a flag that is set then, so that work made of many runs stops
/// before its next one; its result is dropped. Signals are checked once more before
/// returning: nothing converts a result into Python objects (numpy arrays) with a
/// KeyboardInterrupt pending.
fn run_interruptible<R: Send + 'static>(
    py: Python<'_>,
    work: impl FnOnce(&AtomicBool) -> R + Send + 'static,
) -> PyResult<R> {
    run_on_thread(py, work, false).map(|(value, _)| value)
}

/// [`run_interruptible`] for work that stops early and returns what it has when its flag is
/// set (a simulation: `sim::simulate_plan_until`): if `keep`, the first Ctrl-C sets the flag
/// and the call waits for the work's result, returned with `true` (interrupted); a second
/// Ctrl-C meanwhile raises KeyboardInterrupt (the result is dropped). Without `keep`, as
/// [`run_interruptible`].
fn run_on_thread<R: Send + 'static>(
    py: Python<'_>,
    work: impl FnOnce(&AtomicBool) -> R + Send + 'static,
    keep: bool,
) -> PyResult<(R, bool)> {
    let cancel = Arc::new(AtomicBool::new(false));
    let flag = Arc::clone(&cancel);
    let (done, mut result) = sync_channel(1);
    std::thread::Builder::new()
        .name("hilcontact-core".into())
        .spawn(move || {
            let _ = done.send(work(&flag));
        })
        .map_err(|e| PyOSError::new_err(format!("cannot start the simulation's thread: {e}")))?;
    loop {
        // the receiver goes into the GIL-free closure and comes back (it is Send, not Sync)
        let (received, back) = py.allow_threads(move || (result.recv_timeout(SIGNAL_POLL), result));
        result = back;
        if let Err(interrupt) = py.check_signals() {
            if !keep || cancel.load(Ordering::Relaxed) {
                cancel.store(true, Ordering::Relaxed);
                return Err(interrupt);
            }
            cancel.store(true, Ordering::Relaxed);
            // the work ends at its next tick: wait for what it has (a finished result too)
        }
        match received {
            Ok(value) => return Ok((value, cancel.load(Ordering::Relaxed))),
            Err(RecvTimeoutError::Timeout) => continue,
            Err(RecvTimeoutError::Disconnected) => {
                return Err(PanicException::new_err(
                    "the simulation's thread panicked (see the message above)",
                ))
            }
        }
    }
}

/// Loads NumPy's C API now, at import: rust-numpy loads it on the first conversion by running
/// NumPy's Python code, and panics if that raises, as a Ctrl-C landing there makes it do
/// ("Failed to access NumPy array API capsule: KeyboardInterrupt"). A Ctrl-C pending or
/// arriving now raises KeyboardInterrupt from the import instead (the panic caught, its
/// message silenced); a NumPy that cannot be loaded twice in a row is an ImportError.
fn load_numpy(py: Python<'_>) -> PyResult<()> {
    py.check_signals()?;
    let load = || {
        let hook = std::panic::take_hook();
        std::panic::set_hook(Box::new(|_| {}));
        let loaded = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| {
            Vec::<f64>::new().into_pyarray(py);
        }));
        std::panic::set_hook(hook);
        loaded.is_ok()
    };
    if load() {
        return Ok(());
    }
    if load() {
        // the first attempt failed on something that passed: a Ctrl-C, consumed by it
        return Err(PyKeyboardInterrupt::new_err(()));
    }
    Err(PyImportError::new_err(
        "hilcontact._core: cannot load NumPy's C API",
    ))
}

/// A Rust handle held by a Python object until it is finished (or joined): from then on
/// every method raises ValueError with `gone`.
struct Held<T> {
    inner: Option<T>,
    gone: &'static str,
}

impl<T> Held<T> {
    fn get(&self) -> PyResult<&T> {
        self.inner
            .as_ref()
            .ok_or_else(|| PyValueError::new_err(self.gone))
    }

    fn take(&mut self) -> PyResult<T> {
        self.inner
            .take()
            .ok_or_else(|| PyValueError::new_err(self.gone))
    }
}

/// A running real-time HIL loop (`start_hil`). The loop runs in Rust threads; every method
/// returns at once except `wait` and `finish`, which release the GIL.
#[pyclass(module = "hilcontact._core", name = "HilHandle")]
struct PyHilHandle(Held<HilHandle>);

#[pymethods]
impl PyHilHandle {
    /// A snapshot for the live line: phase, tick, time (s), force (N), energy (J),
    /// max_latency_us, overruns, sensor_lost, sensor_late, robot_lost, robot_late, dropped, stop.
    fn status<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyAny>> {
        json_to_py(py, &self.0.get()?.status())
    }

    /// Asks the loop to stop: it commands the robot to hold, stops streaming and flushes.
    fn stop(&self) -> PyResult<()> {
        self.0.get()?.stop();
        Ok(())
    }

    /// Whether the loop has ended.
    fn is_finished(&self) -> PyResult<bool> {
        Ok(self.0.get()?.is_finished())
    }

    /// Waits up to `timeout` seconds (GIL released); returns whether the loop has ended.
    fn wait(&self, py: Python<'_>, timeout: f64) -> PyResult<bool> {
        let handle = self.0.get()?;
        let timeout = Duration::from_secs_f64(timeout.max(0.0));
        Ok(py.allow_threads(|| handle.wait(timeout)))
    }

    /// Waits for the loop and its writer (GIL released) and returns
    /// `{"timeseries": {column: ndarray}, "reference": {...}, "metrics": str, "exit_code": int}`.
    fn finish<'py>(&mut self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        let handle = self.0.take()?;
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

/// A dry run of the real-time HIL loop (`hilcontact check`): opens the sensor and robot links
/// of the runtime options (JSON, as `start_hil`'s) as a run would, listens for `duration` s
/// (GIL released) commanding nothing to the robot, and returns the report as JSON (the Rust
/// `CheckReport`: `sensor`, `robot`, `would_start`, `reasons`). Raises for bad input and for
/// links that cannot be opened (RealtimeError: a port in use, the sensor's counts unreadable).
#[pyfunction]
fn check(
    py: Python<'_>,
    scenario_json: &str,
    options_json: &str,
    duration: f64,
) -> PyResult<String> {
    let report = run_released(py, scenario_json, options_json, |scenario, options| {
        hilcontact_rt::check(scenario, options, duration)
    })?;
    serde_json::to_string(&report).map_err(|e| PyValueError::new_err(e.to_string()))
}

/// Starts the real-time HIL loop of a scenario (JSON) with runtime options (JSON, keys of
/// `RuntimeOptions`: `sensor` and `robot` grouped with their `kind`, defaults for the missing
/// ones). Binds the sockets and reads the sensor's
/// counts per unit before returning; raises RealtimeError if that fails.
#[pyfunction]
fn start_hil(py: Python<'_>, scenario_json: &str, options_json: &str) -> PyResult<PyHilHandle> {
    let handle = run_released(py, scenario_json, options_json, HilHandle::start)?;
    Ok(PyHilHandle(Held {
        inner: Some(handle),
        gone: "the run has been finished already",
    }))
}

/// A running emulated facility (`start_facility`).
#[pyclass(module = "hilcontact._core", name = "FacilityHandle")]
struct PyFacilityHandle(Held<FacilityHandle>);

#[pymethods]
impl PyFacilityHandle {
    /// Counters: finished, tick, time (s), contact_force (N), sensor_protocol, robot_protocol,
    /// sensor and robot (each a dict of packet counters: received, accepted, malformed,
    /// invalid, foreign, stale, lost, late, sent, send_errors, io_errors), io_errors (both
    /// endpoints), overruns, max_latency_us (µs), and the names of earlier versions:
    /// rdt_requests, rdt_bad_requests, corrections, corrections_dropped.
    fn status<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyAny>> {
        json_to_py(py, &self.0.get()?.status())
    }

    /// `{"sensor": "host:port", "http": "host:port" | None, "robot": ..., "robot_peer": ...,
    /// "egm_peer": ...}` (`robot_peer`: where the robot's feedback goes; `egm_peer` is its name
    /// of earlier versions).
    fn addresses<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        let a = self.0.get()?.addresses();
        let d = PyDict::new(py);
        d.set_item("sensor", a.sensor.to_string())?;
        d.set_item("http", a.http.map(|h| h.to_string()))?;
        d.set_item("robot", a.robot.to_string())?;
        d.set_item("robot_peer", a.robot_peer.map(|p| p.to_string()))?;
        d.set_item("egm_peer", a.robot_peer.map(|p| p.to_string()))?;
        Ok(d)
    }

    /// Asks the emulator to stop; returns at once.
    fn stop(&self) -> PyResult<()> {
        self.0.get()?.stop();
        Ok(())
    }

    /// Whether the emulator has ended.
    fn is_finished(&self) -> PyResult<bool> {
        Ok(self.0.get()?.is_finished())
    }

    /// Stops the emulator, waits for it (GIL released) and returns its final counters, with
    /// `live`: the live view's report (None without `--live`) and `scheduling`: what the OS
    /// granted the facility's thread.
    fn join<'py>(&mut self, py: Python<'py>) -> PyResult<Bound<'py, PyAny>> {
        let handle = self.0.take()?;
        let scheduling = serde_json::to_value(handle.scheduling()).unwrap_or_default();
        let (status, live) = py.allow_threads(move || handle.join_with_live());
        let mut value = serde_json::to_value(status).unwrap_or_default();
        value["live"] = live.unwrap_or_default();
        value["scheduling"] = scheduling;
        json_to_py(py, &value)
    }
}

/// Starts the emulated facility of a scenario (JSON) with options (JSON, keys of
/// `EmulatorOptions`: `sensor` and `robot` grouped with their `kind`, defaults for the missing
/// ones). Raises RealtimeError (with `errno`) if a port cannot be bound.
#[pyfunction]
fn start_facility(
    py: Python<'_>,
    scenario_json: &str,
    options_json: &str,
) -> PyResult<PyFacilityHandle> {
    let plan = parse_scenario(py, scenario_json)?;
    hilcontact_core::facility::buildable(&plan).map_err(|e| to_py_err(py, e))?;
    let handle = run_released(py, scenario_json, options_json, FacilityHandle::start)?;
    Ok(PyFacilityHandle(Held {
        inner: Some(handle),
        gone: "the facility has been joined already",
    }))
}

/// The default options of the runtime and the emulator, and the device protocols, as JSON:
/// `{"runtime": {...}, "facility": {...}, "protocols": {"sensor": [...], "robot": [...]},
/// "kinds": {"runtime"|"facility": {"sensor"|"robot": {KIND: {...}}}}}` (`kinds`: every
/// protocol's default options; the one place the defaults and the protocol lists live).
#[pyfunction]
fn realtime_defaults() -> PyResult<String> {
    let value = serde_json::json!({
        "runtime": RuntimeOptions::default(),
        "facility": EmulatorOptions::default(),
        "protocols": {
            "sensor": hilcontact_rt::devices::SENSOR_KINDS,
            "robot": hilcontact_rt::devices::ROBOT_KINDS,
        },
        "kinds": hilcontact_rt::devices::protocol_defaults(),
    });
    Ok(value.to_string())
}

/// The JSON Schema (draft 2020-12) of the real-time options, as JSON text:
/// `{"runtime": <RuntimeOptions>, "facility": <EmulatorOptions>}`, every key with its
/// description (units), default, allowed values and range; `sensor` and `robot` are `oneOf`
/// tagged by `kind` (one variant per protocol).
#[pyfunction]
fn realtime_schema() -> PyResult<String> {
    Ok(hilcontact_rt::options::schema().to_string())
}

fn table_to_dict<'py>(py: Python<'py>, table: Table) -> PyResult<Bound<'py, PyDict>> {
    let dict = PyDict::new(py);
    for (name, values) in table.columns {
        dict.set_item(name, values.into_pyarray(py))?;
    }
    Ok(dict)
}

/// The records of a simulation ([`simulate`]), its tables made when asked: the same columns,
/// to the bit, as `sim::simulate_plan_until`'s tables (building them cost a `paper-table1` run
/// about 0.8 ms, spent only when they are read).
#[pyclass(module = "hilcontact._core", name = "Tables", frozen)]
struct Tables(hilcontact_core::sim::Runs);

#[pymethods]
impl Tables {
    /// The HIL loop's table, `{column: ndarray}` (a new dict of new arrays at each call).
    fn timeseries<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        table_to_dict(py, self.0.timeseries())
    }

    /// The ideal reference's table, `{column: ndarray}` (a new dict of new arrays at each call).
    fn reference<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        table_to_dict(py, self.0.reference_table())
    }
}

/// Runs a scenario (its fully resolved form as JSON): the ideal reference and the HIL loop.
/// Returns `{"tables": Tables, "metrics": str}` (`Tables.timeseries()` and
/// `Tables.reference()`: `{column: ndarray}`, made when called)
/// and, for each output a run can have (`hilcontact_rt::output::OUTPUTS`: `"mcap"`, ...),
/// what it wrote (JSON) or None.
///
/// `outputs`: JSON of the outputs to write the run to, each under its key, with the options a
/// real-time run has under the same key, e.g. `{"mcap": {"path": ..., "overwrite": false,
/// "chunk_interval": 0.5}}`: an MCAP recording by the real-time runtime's recorder, from the
/// run's records; `"mcap"` is then what was written (path, messages, chunks, bytes,
/// write_errors, error, complete). The outputs are opened before the simulation runs: an
/// unknown key or an existing file (without `overwrite`) raises RealtimeOptionError, a path
/// that cannot be created RealtimeError, both naming it.
///
/// Ctrl-C: the first one stops the HIL loop at its next tick (`sim::simulate_plan_until`) and
/// the run so far is returned, with `"interrupted": True`: its metrics' status is
/// `interrupted` (stop `user`, at that tick's time), its tables and metrics cover the ticks
/// run (the reference the same span), the outputs get its records (a live replay stops). A run
/// that had finished when the Ctrl-C came is returned whole, also with `"interrupted": True`.
/// A second Ctrl-C meanwhile raises KeyboardInterrupt. Otherwise `"interrupted"` is False.
#[pyfunction]
#[pyo3(signature = (scenario_json, outputs=None))]
fn simulate<'py>(
    py: Python<'py>,
    scenario_json: &str,
    outputs: Option<&str>,
) -> PyResult<Bound<'py, PyDict>> {
    let plan = parse_scenario(py, scenario_json)?;
    hilcontact_core::facility::buildable(&plan).map_err(|e| to_py_err(py, e))?;
    let outputs = match outputs {
        Some(json) => {
            let options: serde_json::Value = parse_options(py, json)?;
            let info = RunInfo::new(&plan, false);
            let opened = py
                .allow_threads(|| Outputs::open_only(&plan, &info, &options))
                .map_err(|e| rt_err(py, e))?;
            Some((opened, info))
        }
        None => None,
    };
    let work = move |stop: &AtomicBool| {
        let runs = hilcontact_core::sim::simulate_plan_records_until(&plan, stop);
        let reports = match outputs {
            Some((outputs, info)) if !outputs.is_empty() => {
                outputs.record_simulation_until(&info, &runs.hil.rows, &runs.metrics, stop)
            }
            _ => Vec::new(),
        };
        (runs, reports)
    };
    let ((runs, reports), interrupted) = run_on_thread(py, work, true)?;
    let metrics =
        serde_json::to_string(&runs.metrics).map_err(|e| PyValueError::new_err(e.to_string()))?;
    let result = PyDict::new(py);
    result.set_item("tables", Bound::new(py, Tables(runs))?)?;
    result.set_item("metrics", metrics)?;
    result.set_item("interrupted", interrupted)?;
    for o in OUTPUTS {
        result.set_item(o.key, py.None())?;
    }
    for (key, report) in reports {
        let report =
            serde_json::to_string(&report).map_err(|e| PyValueError::new_err(e.to_string()))?;
        result.set_item(key, report)?;
    }
    Ok(result)
}

/// Runs many scenarios (each its resolved form as JSON) in parallel on Rust threads, the GIL
/// released, keeping only each run's summary (no time series). `threads`: size of the thread
/// pool (default: rayon's global pool, one thread per core). Runs with the same ideal
/// reference (`sim::reference_key`: they differ only in the facility, the compensator or the
/// seed) share its computation, which gives each the same numbers, to the bit.
///
/// Returns columns, one value per scenario in the given order: `status` (list of "ok" /
/// "unfaithful" / "diverged"), then one array per column of [`summary_columns`] (the core's
/// `RunSummary::COLUMNS` and `wall_time`, s; NaN where a run has no such value).
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
        .map(|json| {
            let plan = parse_scenario(py, json)?;
            hilcontact_core::facility::buildable(&plan).map_err(|e| to_py_err(py, e))?;
            Ok(plan)
        })
        .collect::<PyResult<Vec<_>>>()?;
    // the runs that share an ideal reference (same `reference_key`: e.g. they differ only in
    // the facility or the compensator) share its computation: `shared[i]` is run i's index
    // into `distinct`, the first run of each reference
    let (distinct, shared) = {
        use std::collections::HashMap;
        let mut index: HashMap<String, usize> = HashMap::new();
        let mut distinct = Vec::new();
        let mut shared = Vec::with_capacity(parsed.len());
        for (i, plan) in parsed.iter().enumerate() {
            let next = distinct.len();
            let j = *index
                .entry(hilcontact_core::sim::reference_key(plan))
                .or_insert(next);
            if j == next {
                distinct.push(i);
            }
            shared.push(j);
        }
        (distinct, shared)
    };
    // on Ctrl-C, the runs not yet started are skipped (the call raises KeyboardInterrupt)
    let results = run_interruptible(py, move |cancel| {
        let run_all = || {
            // each reference once, with its wall time shared among the runs that use it
            let references = distinct
                .par_iter()
                .map(|&i| {
                    let start = std::time::Instant::now();
                    let trace = hilcontact_core::sim::run_reference(&parsed[i], false).0;
                    (trace, start.elapsed().as_secs_f64())
                })
                .collect::<Vec<_>>();
            let mut users = vec![0usize; references.len()];
            for &j in &shared {
                users[j] += 1;
            }
            parsed
                .par_iter()
                .zip(shared.par_iter())
                .map(|(s, &j)| {
                    if cancel.load(Ordering::Relaxed) {
                        return None;
                    }
                    let start = std::time::Instant::now();
                    let (reference, reference_time) = &references[j];
                    let metrics =
                        hilcontact_core::sim::simulate_plan_metrics_with_reference(s, reference);
                    let wall_time =
                        start.elapsed().as_secs_f64() + reference_time / users[j] as f64;
                    Some((metrics, wall_time))
                })
                .collect::<Option<Vec<_>>>()
        };
        match threads {
            None => Ok(run_all()),
            Some(n) => rayon::ThreadPoolBuilder::new()
                .num_threads(n.max(1))
                .build()
                .map(|pool| pool.install(run_all))
                .map_err(|e| format!("thread pool of {n} threads: {e}")),
        }
    })?
    .map_err(PyValueError::new_err)?
    .ok_or_else(|| PyKeyboardInterrupt::new_err(()))?;
    use hilcontact_core::sweep::RunSummary;
    let n = results.len();
    let mut status = Vec::with_capacity(n);
    let mut columns: Vec<Vec<f64>> = vec![Vec::with_capacity(n); RunSummary::COLUMNS.len() + 1];
    for (metrics, wall_time) in results {
        let row = RunSummary::of(&metrics);
        status.push(
            serde_json::to_value(row.status)
                .map_err(|e| PyValueError::new_err(e.to_string()))?
                .as_str()
                .unwrap_or("")
                .to_string(),
        );
        for (column, value) in columns
            .iter_mut()
            .zip(row.values.iter().chain([&wall_time]))
        {
            column.push(*value);
        }
    }
    let result = PyDict::new(py);
    result.set_item("status", status)?;
    let names = RunSummary::COLUMNS
        .iter()
        .map(|c| c.name)
        .chain(["wall_time"]);
    for (name, values) in names.zip(columns) {
        result.set_item(name, values.into_pyarray(py))?;
    }
    Ok(result)
}

/// The undamped contact frequency of a scenario's linear contact, Hz (`√(k/μ) / 2π`, μ the
/// reduced mass), NaN for a Hunt-Crossley contact. Raises ScenarioError for an invalid one.
#[pyfunction]
fn contact_frequency(py: Python<'_>, scenario_json: &str) -> PyResult<f64> {
    Ok(parse_scenario(py, scenario_json)?
        .contact_frequency()
        .unwrap_or(f64::NAN))
}

/// The columns of the tables a run produces, with their units: a dict with `timeseries` (the
/// HIL loop), `reference` and `realtime` (what a real-time run adds to `timeseries`), each a
/// list of `(name, unit, only)` in order, `only` being "always", "estimates" (compensators
/// that identify the contact) or "observed_energy" (compensators with an energy observer).
#[pyfunction]
fn table_columns(py: Python<'_>) -> PyResult<Bound<'_, PyDict>> {
    use hilcontact_core::sim::{columns, Only, HIL_FIELDS, REFERENCE_FIELDS};
    let list = |cols: Vec<(String, &'static str, Only)>| {
        cols.into_iter()
            .map(|(name, unit, only)| {
                let only = match only {
                    Only::Always => "always",
                    Only::Estimates => "estimates",
                    Only::ObservedEnergy => "observed_energy",
                };
                (name, unit, only)
            })
            .collect::<Vec<_>>()
    };
    let result = PyDict::new(py);
    result.set_item("timeseries", list(columns(&HIL_FIELDS)))?;
    result.set_item("reference", list(columns(&REFERENCE_FIELDS)))?;
    result.set_item(
        "realtime",
        list(columns(&hilcontact_rt::report::REALTIME_FIELDS)),
    )?;
    Ok(result)
}

/// The columns of a run's summary row (what `simulate_batch` returns after `status`), in
/// order: a list of `(name, unit, meaning)`; the core's `RunSummary::COLUMNS`, then
/// `wall_time` (s).
#[pyfunction]
fn summary_columns() -> Vec<(&'static str, &'static str, &'static str)> {
    use hilcontact_core::sweep::RunSummary;
    RunSummary::COLUMNS
        .iter()
        .map(|c| (c.name, c.unit, c.doc))
        .chain([(
            "wall_time",
            "s",
            "wall-clock time of the run (its share of a reference computed once for several runs)",
        )])
        .collect()
}

/// The compensator registry, as JSON: a list, in the registry's order, of
/// `{"kind", "summary", "colour", "defaults": {"kind": ..., parameter: default, ...}}`
/// (the one list of compensators: Python's allowed kinds, defaults and plot colours).
#[pyfunction]
fn compensator_registry() -> PyResult<String> {
    use hilcontact_core::compensator::REGISTRY;
    let entries = REGISTRY
        .iter()
        .map(|k| {
            Ok(serde_json::json!({
                "kind": k.kind,
                "summary": k.summary.trim(),
                "colour": k.colour,
                "defaults": serde_json::to_value((k.default)())
                    .map_err(|e| PyValueError::new_err(e.to_string()))?,
            }))
        })
        .collect::<PyResult<Vec<_>>>()?;
    Ok(serde_json::Value::Array(entries).to_string())
}

/// The JSON Schema of a scenario file (draft 2020-12), as JSON text: every key with its
/// description (units), default, allowed values and range, the compensator as a union
/// tagged by `kind`, and `x-value` (`vec3`, `quaternion`, `inertia`) on vectors. The one
/// schema: Python builds its scenario models from it.
#[pyfunction]
fn scenario_schema() -> PyResult<String> {
    serde_json::to_string(&hilcontact_core::schema::scenario_schema())
        .map_err(|e| PyValueError::new_err(e.to_string()))
}

/// Resolves a scenario (JSON) as a run would: returns the resolved scenario as JSON (defaults
/// filled in, quaternions and normals normalised, inertia as a symmetric tensor, wall names
/// set, delays rounded with `facility.round_delays`). Raises ScenarioError listing every
/// problem in `issues`.
#[pyfunction]
fn resolve_scenario(py: Python<'_>, scenario_json: &str) -> PyResult<String> {
    let plan = parse_scenario(py, scenario_json)?;
    serde_json::to_string(&plan.scenario).map_err(|e| PyValueError::new_err(e.to_string()))
}

/// Version of the native core.
#[pyfunction]
fn version() -> &'static str {
    env!("CARGO_PKG_VERSION")
}

/// A recording given as `{column: 1-D float array}` (names as in a run's timeseries.parquet).
fn recording_table(columns: &Bound<'_, PyDict>) -> PyResult<Table> {
    let mut table = Table::default();
    for (name, values) in columns.iter() {
        let name: String = name.extract()?;
        let values: Vec<f64> = values.extract()?;
        table.columns.push((name, values));
    }
    Ok(table)
}

/// A bad recording: `ScenarioError` with the core's one-line message.
fn recording_err(py: Python<'_>, error: hilcontact_core::RecordingError) -> PyErr {
    raise(py, |c| &c.scenario, format!("recording: {error}"))
}

/// Replays a recording (`{column: array}`: time, measured_force_*, measured_moment_* in the
/// sensor frame, actual_tip_position_*, actual_tip_velocity_*, tip_position_*, tip_velocity_*
/// in `t`) through the compensator of a scenario (resolved JSON), built as the live loop
/// builds it. Returns `{column: ndarray}`: time, applied_force_*, applied_moment_* (sensor
/// frame), velocity_correction_*, stiffness_estimate, damping_estimate, observed_energy.
/// Raises ScenarioError for a bad scenario or recording.
#[pyfunction]
fn replay<'py>(
    py: Python<'py>,
    scenario_json: &str,
    columns: &Bound<'py, PyDict>,
) -> PyResult<Bound<'py, PyDict>> {
    let plan = parse_scenario(py, scenario_json)?;
    let table = recording_table(columns)?;
    let out = py.allow_threads(|| -> Result<Table, hilcontact_core::RecordingError> {
        let recording = hilcontact_core::replay::Recording::from_table(&table, true)?;
        hilcontact_core::replay::replay_plan(&plan, &recording)
    });
    table_to_dict(py, out.map_err(|e| recording_err(py, e))?)
}

/// Identifies the contacts of a recording (columns as `replay`'s, the desired tip not needed)
/// with the identification front end of a scenario's compensator (its parameters, sensor delay
/// and attitude). Returns `{"timeseries": {column: ndarray}, "collisions": [dict]}`, each
/// collision with index, start, end (s), samples, updates, stiffness, stiffness_std (N/m),
/// damping, damping_std (N s/m), normal (unit, `t`), normal_std (rad), point (`t`, m),
/// offset_std (m), peak_force (N), frictional (bool), friction (μ̂), friction_std,
/// sliding_samples.
#[pyfunction]
fn identify<'py>(
    py: Python<'py>,
    scenario_json: &str,
    columns: &Bound<'py, PyDict>,
) -> PyResult<Bound<'py, PyDict>> {
    let plan = parse_scenario(py, scenario_json)?;
    let table = recording_table(columns)?;
    let out = py.allow_threads(|| {
        let recording = hilcontact_core::replay::Recording::from_table(&table, false)?;
        hilcontact_core::identify::identify_plan(&plan, &recording)
    });
    let id = out.map_err(|e| recording_err(py, e))?;
    let collisions = id
        .collisions
        .iter()
        .map(|c| {
            serde_json::json!({
                "index": c.index, "start": c.start, "end": c.end, "samples": c.samples,
                "updates": c.updates, "stiffness": c.stiffness, "stiffness_std": c.stiffness_std,
                "damping": c.damping, "damping_std": c.damping_std,
                "normal": [c.normal.x, c.normal.y, c.normal.z], "normal_std": c.normal_std,
                "point": [c.point.x, c.point.y, c.point.z], "offset_std": c.offset_std,
                "peak_force": c.peak_force,
                "frictional": c.frictional, "friction": c.friction,
                "friction_std": if c.friction_std.is_finite() { c.friction_std } else { f64::NAN },
                "sliding_samples": c.sliding_samples,
            })
        })
        .collect::<Vec<_>>();
    let result = PyDict::new(py);
    result.set_item("timeseries", table_to_dict(py, id.timeseries)?)?;
    result.set_item("collisions", json_to_py(py, &collisions)?)?;
    Ok(result)
}

/// The live loop's own identification at the end of a run, replayed over its recording
/// (columns as `identify`'s) with the scenario compensator's front end as the loop runs it
/// (one filter, never restarted): `{stiffness, stiffness_std (N/m), damping, damping_std
/// (N s/m), updates, contacts}`, or None before any update. Raises like `replay`.
#[pyfunction]
fn online_identification<'py>(
    py: Python<'py>,
    scenario_json: &str,
    columns: &Bound<'py, PyDict>,
) -> PyResult<Option<Bound<'py, PyDict>>> {
    let plan = parse_scenario(py, scenario_json)?;
    let table = recording_table(columns)?;
    let out = py.allow_threads(|| {
        let recording = hilcontact_core::replay::Recording::from_table(&table, false)?;
        hilcontact_core::identify::online_identification_plan(&plan, &recording)
    });
    let Some(o) = out.map_err(|e| recording_err(py, e))? else {
        return Ok(None);
    };
    let result = PyDict::new(py);
    result.set_item("stiffness", o.stiffness)?;
    result.set_item("stiffness_std", o.stiffness_std)?;
    result.set_item("damping", o.damping)?;
    result.set_item("damping_std", o.damping_std)?;
    result.set_item("updates", o.updates)?;
    result.set_item("contacts", o.contacts)?;
    Ok(Some(result))
}

/// The frame maths of a run's figures, from the core's resolved scenario (its sensor attitude
/// and its walls, normals normalised), vectorised over a run's rows:
///
/// - `in_t`: `sensor_vectors` (rows of x, y, z in the sensor frame, e.g. the applied moment,
///   N m) turned into the target frame `t` (same unit); None without `sensor_vectors`.
/// - `normals`: the walls' unit normals in `t`, one row per wall (`[[walls]]` order).
/// - `distances`: per array of `points` (rows of x, y, z in `t`, m, e.g. the rod tip), the
///   signed distance of each point to each wall's plane along its normal, m (< 0: inside),
///   as an array of (walls, rows).
///
/// Raises ScenarioError for a bad scenario, ValueError for an array that is not (rows, 3).
#[pyfunction]
#[pyo3(signature = (scenario_json, sensor_vectors=None, points=Vec::new()))]
fn frames<'py>(
    py: Python<'py>,
    scenario_json: &str,
    sensor_vectors: Option<numpy::PyReadonlyArray2<'py, f64>>,
    points: Vec<numpy::PyReadonlyArray2<'py, f64>>,
) -> PyResult<Bound<'py, PyDict>> {
    use numpy::ndarray::Array2;
    use numpy::PyUntypedArrayMethods;

    fn rows(array: &numpy::PyReadonlyArray2<'_, f64>) -> PyResult<Vec<nalgebra::Vector3<f64>>> {
        let view = array.as_array();
        if view.ncols() != 3 {
            return Err(PyValueError::new_err(format!(
                "expected rows of (x, y, z), got an array of shape {:?}",
                array.shape()
            )));
        }
        Ok(view
            .rows()
            .into_iter()
            .map(|r| nalgebra::Vector3::new(r[0], r[1], r[2]))
            .collect())
    }
    let plan = parse_scenario(py, scenario_json)?;
    let walls = &plan.system.contact.walls;
    let result = PyDict::new(py);
    let in_t = match sensor_vectors {
        None => None,
        Some(array) => {
            let q = plan.sensor.orientation;
            let turned = rows(&array)?.iter().map(|v| q * v).collect::<Vec<_>>();
            let flat = turned.iter().flat_map(|v| [v.x, v.y, v.z]).collect();
            let out = Array2::from_shape_vec((turned.len(), 3), flat)
                .map_err(|e| PyValueError::new_err(e.to_string()))?;
            Some(out.into_pyarray(py))
        }
    };
    result.set_item("in_t", in_t)?;
    let normals = walls
        .iter()
        .flat_map(|w| [w.normal.x, w.normal.y, w.normal.z])
        .collect();
    let normals = Array2::from_shape_vec((walls.len(), 3), normals)
        .map_err(|e| PyValueError::new_err(e.to_string()))?;
    result.set_item("normals", normals.into_pyarray(py))?;
    let mut distances = Vec::new();
    for array in &points {
        let tips = rows(array)?;
        let flat = walls
            .iter()
            .flat_map(|w| tips.iter().map(move |p| w.signed_distance(p)))
            .collect();
        let out = Array2::from_shape_vec((walls.len(), tips.len()), flat)
            .map_err(|e| PyValueError::new_err(e.to_string()))?;
        distances.push(out.into_pyarray(py));
    }
    result.set_item("distances", distances)?;
    Ok(result)
}

/// glibc's allocator keeps freed memory instead of handing it back to the system at once: a
/// run's time series (a few MB of columns, then the records and pandas' copies) were each a
/// fresh `mmap` faulted in page by page and unmapped at the end, which cost about as much as
/// the simulation itself (docs/performance.md). Allocations up to 32 MiB come from the heap,
/// and up to 64 MiB of free memory at its top is kept for the next run. Other allocators are
/// left as they are.
#[cfg(all(target_os = "linux", target_env = "gnu"))]
fn keep_freed_memory() {
    extern "C" {
        fn mallopt(param: std::os::raw::c_int, value: std::os::raw::c_int) -> std::os::raw::c_int;
    }
    const M_TRIM_THRESHOLD: std::os::raw::c_int = -1;
    const M_MMAP_THRESHOLD: std::os::raw::c_int = -3;
    // SAFETY: mallopt only sets allocator parameters; a refused value leaves them unchanged.
    unsafe {
        mallopt(M_MMAP_THRESHOLD, 32 << 20);
        mallopt(M_TRIM_THRESHOLD, 64 << 20);
    }
}

#[cfg(not(all(target_os = "linux", target_env = "gnu")))]
fn keep_freed_memory() {}

/// `hilcontact calibrate --simulate`: the calibration procedure against the scenario's
/// simulated facility (hilcontact_rt::calibrate::simulate). `options_json` holds the
/// procedure's options (`CalibrateOptions`); `force_limit` the run's force limit, N;
/// `on_progress(line)` gets each progress line as it comes. Returns `{"calibration": dict or
/// None, "error": str or None, "progress": [str], "duration": s, "peak_force": N,
/// "final_force": N}`.
#[pyfunction]
#[pyo3(signature = (scenario_json, options_json, force_limit, measured_at, on_progress=None))]
fn calibrate_simulated<'py>(
    py: Python<'py>,
    scenario_json: &str,
    options_json: &str,
    force_limit: f64,
    measured_at: &str,
    on_progress: Option<Bound<'py, PyAny>>,
) -> PyResult<Bound<'py, PyAny>> {
    let plan = parse_scenario(py, scenario_json)?;
    let options: hilcontact_rt::calibrate::CalibrateOptions = parse_options(py, options_json)?;
    let outcome =
        hilcontact_rt::calibrate::simulate(&plan, &options, force_limit, measured_at, |line| {
            if let Some(callback) = &on_progress {
                // best effort: a failing callback does not stop the procedure
                let _ = callback.call1((line,));
            }
        })
        .map_err(|message| raise(py, |c| &c.option, message))?;
    json_to_py(
        py,
        &serde_json::json!({
            "calibration": outcome.file,
            "error": outcome.error,
            "progress": outcome.progress,
            "duration": outcome.duration,
            "peak_force": outcome.peak_force,
            "final_force": outcome.final_force,
        }),
    )
}

/// The JSON Schema of the calibration file and of the procedure's options:
/// `{"file": ..., "options": ...}`.
#[pyfunction]
fn calibration_schema() -> PyResult<String> {
    Ok(hilcontact_rt::calibrate::schema().to_string())
}

#[pymodule]
fn _core(m: &Bound<'_, PyModule>) -> PyResult<()> {
    keep_freed_memory();
    load_numpy(m.py())?;
    m.add_function(wrap_pyfunction!(simulate, m)?)?;
    m.add_function(wrap_pyfunction!(simulate_batch, m)?)?;
    m.add_function(wrap_pyfunction!(summary_columns, m)?)?;
    m.add_function(wrap_pyfunction!(table_columns, m)?)?;
    m.add_function(wrap_pyfunction!(contact_frequency, m)?)?;
    m.add_function(wrap_pyfunction!(version, m)?)?;
    m.add_function(wrap_pyfunction!(compensator_registry, m)?)?;
    m.add_function(wrap_pyfunction!(scenario_schema, m)?)?;
    m.add_function(wrap_pyfunction!(resolve_scenario, m)?)?;
    m.add_function(wrap_pyfunction!(start_hil, m)?)?;
    m.add_function(wrap_pyfunction!(start_facility, m)?)?;
    m.add_function(wrap_pyfunction!(check, m)?)?;
    m.add_function(wrap_pyfunction!(realtime_defaults, m)?)?;
    m.add_function(wrap_pyfunction!(realtime_schema, m)?)?;
    m.add_function(wrap_pyfunction!(replay, m)?)?;
    m.add_function(wrap_pyfunction!(identify, m)?)?;
    m.add_function(wrap_pyfunction!(online_identification, m)?)?;
    m.add_function(wrap_pyfunction!(frames, m)?)?;
    m.add_function(wrap_pyfunction!(mesh::read_mesh, m)?)?;
    m.add_function(wrap_pyfunction!(calibrate_simulated, m)?)?;
    m.add_function(wrap_pyfunction!(calibration_schema, m)?)?;
    m.add_function(wrap_pyfunction!(calibrate::start_calibration, m)?)?;
    m.add_class::<calibrate::PyCalibrationHandle>()?;
    m.add_function(wrap_pyfunction!(plugin::simulate_python, m)?)?;
    m.add_function(wrap_pyfunction!(plugin::compensator_context, m)?)?;
    m.add_function(wrap_pyfunction!(facility::simulate_facility, m)?)?;
    m.add_class::<PyHilHandle>()?;
    m.add_class::<Tables>()?;
    m.add_class::<PyFacilityHandle>()?;
    let errors = error_classes(m.py())?;
    m.add("HilContactError", errors.base.clone_ref(m.py()))?;
    m.add("ScenarioError", errors.scenario.clone_ref(m.py()))?;
    m.add("RealtimeError", errors.realtime.clone_ref(m.py()))?;
    m.add("RealtimeOptionError", errors.option.clone_ref(m.py()))?;
    Ok(())
}
