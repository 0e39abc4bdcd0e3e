//! `hilcontact calibrate` over the device links: the binding of
//! [`hilcontact_rt::calibrate::CalibrationHandle`] (a real-time calibration, started like
//! `start_hil`).

use std::time::Duration;

use hilcontact_rt::calibrate::{CalibrateOptions, CalibrationHandle};
use hilcontact_rt::RuntimeOptions;
use pyo3::prelude::*;

use crate::{json_to_py, parse_options, rt_err, run_released, Held};

/// A running real-time calibration (`start_calibration`). The loop runs in Rust threads;
/// every method returns at once except `wait` and `finish`, which release the GIL.
#[pyclass(module = "hilcontact._core", name = "CalibrationHandle")]
pub(crate) struct PyCalibrationHandle(Held<CalibrationHandle>);

#[pymethods]
impl PyCalibrationHandle {
    /// A snapshot for the live line (as `HilHandle.status`; energy is 0).
    fn status<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyAny>> {
        json_to_py(py, &self.0.get()?.status())
    }

    /// The progress lines since the last call, surface by surface.
    fn progress(&self) -> PyResult<Vec<String>> {
        Ok(self.0.get()?.progress())
    }

    /// Asks the loop to stop: the robot backs out of contact, holds; streaming stops.
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

    /// Waits for the end (GIL released) and returns `{"calibration": dict or None, "error":
    /// str or None, "progress": [str], "duration": s, "wall_seconds": [s], "peak_force": N,
    /// "final_force": N, "exit_code": int, "realtime": dict}` (the loop's stop, timing and
    /// counters). Raises RealtimeError when the loop never started.
    fn finish<'py>(&mut self, py: Python<'py>) -> PyResult<Bound<'py, PyAny>> {
        let handle = self.0.take()?;
        let end = py
            .allow_threads(move || handle.finish())
            .map_err(|e| rt_err(py, e))?;
        let o = &end.outcome;
        json_to_py(
            py,
            &serde_json::json!({
                "calibration": o.file,
                "error": o.error,
                "progress": o.progress,
                "duration": o.duration,
                "wall_seconds": o.wall_seconds,
                "peak_force": o.peak_force,
                "final_force": o.final_force,
                "exit_code": end.exit_code,
                "realtime": end.realtime,
            }),
        )
    }
}

/// Starts `hilcontact calibrate` over the device links: the scenario (JSON), the runtime
/// options (JSON, as `start_hil`'s; `limits.force_limit` is the force limit the procedure
/// presses a fifth of), the procedure's options (JSON, `CalibrateOptions`) and the time stamp
/// written into the file. Binds the sockets before returning; raises RealtimeError if that
/// fails, RealtimeOptionError for options the procedure refuses (before anything is opened).
#[pyfunction]
pub(crate) fn start_calibration(
    py: Python<'_>,
    scenario_json: &str,
    options_json: &str,
    procedure_json: &str,
    measured_at: &str,
) -> PyResult<PyCalibrationHandle> {
    let procedure: CalibrateOptions = parse_options(py, procedure_json)?;
    let handle = run_released(
        py,
        scenario_json,
        options_json,
        |scenario, options: &RuntimeOptions| {
            CalibrationHandle::start(scenario, options, &procedure, measured_at)
        },
    )?;
    Ok(PyCalibrationHandle(Held {
        inner: Some(handle),
        gone: "the calibration has been finished already",
    }))
}
