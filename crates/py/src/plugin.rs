//! A compensator written in Python in the core's HIL loop: [`PyCompensator`] implements the
//! core's `Compensator` trait by calling a Python object's `step` each tick (the adapter of
//! `hilcontact.plugin`, which wraps the user's `hilcontact.Compensator`, checks what it
//! returns and times it). Frames are turned here: the adapter sees the wrenches in the sensor
//! frame, the core in `t`. No numerics beyond the rotation.

use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex};

use hilcontact_core::compensator::{
    Compensator, CompensatorInput, CompensatorOutput, ContactEstimate,
};
use hilcontact_core::frames::FrameWrench;
use hilcontact_core::hil::compensator_context as core_context;
use nalgebra::{UnitQuaternion, Vector3};
use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;
use pyo3::types::{PyDict, PyTuple};

/// Numbers handed to the adapter's `step` each tick, in this order: time k·T (s), measured force
/// (sensor frame, N, 3), measured moment (about the sensor origin, sensor frame, N·m, 3),
/// actual tip position (`t`, m, 3) and velocity (m/s, 3), desired tip position (m, 3) and
/// velocity (m/s, 3), tip mobility (`t`, 1/kg, 9, row-major; zeros unless the compensator
/// `uses_tip_mobility`).
pub const INPUT_LEN: usize = 1 + 6 * 3 + 9;

/// Numbers the adapter's `step` returns, in this order: applied force (sensor frame, N, 3),
/// applied moment (sensor frame, N·m, 3), velocity correction (`t`, m/s, 3), stiffness
/// estimate (N/m), damping estimate (N·s/m), observed energy (J) (NaN where not reported).
pub const OUTPUT_LEN: usize = 12;

/// The core's `Compensator` around a Python adapter. A failed call (the adapter raises: the
/// user's exception, a bad output, a step over its time limit, Ctrl-C) is kept in `fault` and
/// the tick returns a non-finite wrench, which stops the run at that tick
/// (`StopKind::NonFinite`); the caller then raises the kept error.
struct PyCompensator {
    adapter: Py<PyAny>,
    /// Sensor attitude in `t` (sensor to `t`).
    sensor_to_t: UnitQuaternion<f64>,
    tick: usize,
    /// Control period T, s.
    period: f64,
    estimates: bool,
    energy: bool,
    mobility: bool,
    fault: Arc<Mutex<Option<PyErr>>>,
    /// The user's stop (Ctrl-C): set once the adapter's `interrupted` is true after a tick
    /// (`hilcontact.plugin.stop_on_interrupt`); the HIL loop ends the run at that tick.
    stop: Arc<AtomicBool>,
}

impl PyCompensator {
    fn call(&self, py: Python<'_>, input: &CompensatorInput) -> PyResult<[f64; OUTPUT_LEN]> {
        let to_sensor = self.sensor_to_t.inverse();
        let mut data = [0.0; INPUT_LEN];
        data[0] = self.tick as f64 * self.period;
        let vectors = [
            to_sensor * input.measured.force,
            to_sensor * input.measured.moment,
            input.tip_position_actual,
            input.tip_velocity_actual,
            input.tip_position_desired,
            input.tip_velocity_desired,
        ];
        for (i, v) in vectors.iter().enumerate() {
            data[1 + 3 * i..4 + 3 * i].copy_from_slice(v.as_slice());
        }
        for r in 0..3 {
            for c in 0..3 {
                data[19 + 3 * r + c] = input.tip_mobility[(r, c)];
            }
        }
        let args = PyTuple::new(py, data)?;
        let output = self
            .adapter
            .call_method1(py, "step_flat", (self.tick, args))?
            .extract(py)?;
        // a Ctrl-C meanwhile (its handler ran in the step): the run ends at this tick
        // (an adapter without the attribute is never interrupted)
        let interrupted = self.adapter.bind(py).getattr("interrupted").ok();
        if interrupted.map_or(Ok(false), |v| v.is_truthy())? {
            self.stop.store(true, Ordering::Relaxed);
        }
        Ok(output)
    }
}

impl Compensator for PyCompensator {
    fn step(&mut self, input: &CompensatorInput) -> CompensatorOutput {
        let result = Python::with_gil(|py| self.call(py, input));
        self.tick += 1;
        match result {
            Ok(o) => {
                let v = |i: usize| Vector3::new(o[i], o[i + 1], o[i + 2]);
                CompensatorOutput {
                    applied: FrameWrench {
                        force: self.sensor_to_t * v(0),
                        moment: self.sensor_to_t * v(3),
                    },
                    velocity_correction: v(6),
                    estimate: self.estimates.then_some(ContactEstimate {
                        stiffness: o[9],
                        damping: o[10],
                    }),
                    observed_energy: o[11],
                }
            }
            Err(error) => {
                let mut fault = self.fault.lock().unwrap_or_else(|e| e.into_inner());
                fault.get_or_insert(error);
                let nan = Vector3::repeat(f64::NAN);
                CompensatorOutput::wrench(FrameWrench {
                    force: nan,
                    moment: nan,
                })
            }
        }
    }

    fn reset(&mut self) {
        self.tick = 0;
    }

    fn estimates_contact(&self) -> bool {
        self.estimates
    }

    fn observes_energy(&self) -> bool {
        self.energy
    }

    fn uses_tip_mobility(&self) -> bool {
        self.mobility
    }
}

/// Runs a scenario (resolved JSON) with a compensator written in Python in place of its
/// `[compensator]`: `adapter` (a `hilcontact.plugin` adapter) gets `reset(context)` once, with
/// `context` a dict (`period` s, `sensor_delay_ticks`, `sensor_delay` s, `sensor_origin` `t`
/// m, `sensor_orientation` [w, x, y, z] sensor to `t`, `sensor_rotation` the same as a row-major
/// 3x3 matrix, `reduced_mass` kg), then
/// `step_flat(k, numbers)` each tick (see `INPUT_LEN`, `OUTPUT_LEN`); its attributes
/// `estimates_contact`, `observes_energy`, `uses_tip_mobility` (bool) say what it reports.
/// The GIL is released between ticks. A true `interrupted` attribute of the adapter after a
/// tick (set by a Ctrl-C, `hilcontact.plugin.stop_on_interrupt`) ends the run at that tick as
/// a user stop (`sim::simulate_plan_with_compensator_until`): status `interrupted`, the tables
/// and metrics up to there, and `"interrupted": True` in the result (else False). Returns
/// what `simulate` returns (no outputs), with
/// `metrics.compensator` set to `name`, and `summary`: the run's sweep row (`status` and the
/// columns of `summary_columns()` but `wall_time`). An error raised by the adapter stops the run at that
/// tick and is raised again here, nothing returned.
#[pyfunction]
pub fn simulate_python<'py>(
    py: Python<'py>,
    scenario_json: &str,
    adapter: Py<PyAny>,
    name: &str,
) -> PyResult<Bound<'py, PyDict>> {
    let plan = crate::parse_scenario(py, scenario_json)?;
    hilcontact_core::facility::buildable(&plan).map_err(|e| crate::to_py_err(py, e))?;
    let q = plan.sensor.orientation;
    let ctx = context_dict(py, &plan)?;
    let bound = adapter.bind(py);
    bound.call_method1("reset", (ctx,))?;
    let flag = |name: &str| -> PyResult<bool> { bound.getattr(name)?.is_truthy() };
    let fault = Arc::new(Mutex::new(None));
    let stop = Arc::new(AtomicBool::new(false));
    let compensator = PyCompensator {
        sensor_to_t: q,
        tick: 0,
        period: plan.period,
        estimates: flag("estimates_contact")?,
        energy: flag("observes_energy")?,
        mobility: flag("uses_tip_mobility")?,
        fault: fault.clone(),
        stop: stop.clone(),
        adapter: adapter.clone_ref(py),
    };
    let (output, _) = py.allow_threads(|| {
        hilcontact_core::sim::simulate_plan_with_compensator_until(
            &plan,
            Box::new(compensator),
            true,
            &stop,
        )
    });
    if let Some(error) = fault.lock().unwrap_or_else(|e| e.into_inner()).take() {
        return Err(error);
    }
    let row = hilcontact_core::sweep::RunSummary::of(&output.metrics);
    let summary = PyDict::new(py);
    summary.set_item(
        "status",
        serde_json::to_value(row.status)
            .map_err(|e| PyValueError::new_err(e.to_string()))?
            .as_str()
            .unwrap_or(""),
    )?;
    for (column, value) in hilcontact_core::sweep::RunSummary::COLUMNS
        .iter()
        .zip(row.values)
    {
        summary.set_item(column.name, value)?;
    }
    let mut metrics =
        serde_json::to_value(&output.metrics).map_err(|e| PyValueError::new_err(e.to_string()))?;
    metrics["compensator"] = serde_json::Value::from(name);
    let result = PyDict::new(py);
    result.set_item("timeseries", crate::table_to_dict(py, output.timeseries)?)?;
    result.set_item("reference", crate::table_to_dict(py, output.reference)?)?;
    result.set_item("metrics", metrics.to_string())?;
    result.set_item("summary", summary)?;
    result.set_item("interrupted", stop.load(Ordering::Relaxed))?;
    Ok(result)
}

/// The facts a compensator of `plan` is built with, as the dict `reset(context)` gets.
fn context_dict<'py>(
    py: Python<'py>,
    plan: &hilcontact_core::Plan,
) -> PyResult<Bound<'py, PyDict>> {
    let context = core_context(plan);
    let q = plan.sensor.orientation;
    let ctx = PyDict::new(py);
    ctx.set_item("period", context.period)?;
    ctx.set_item("sensor_delay_ticks", context.sensor_delay_ticks)?;
    ctx.set_item("sensor_delay", context.sensor_delay())?;
    ctx.set_item("sensor_origin", context.sensor_origin.as_slice().to_vec())?;
    ctx.set_item("sensor_orientation", vec![q.w, q.i, q.j, q.k])?;
    let r = q.to_rotation_matrix();
    let rows: Vec<f64> = (0..9).map(|i| r[(i / 3, i % 3)]).collect();
    ctx.set_item("sensor_rotation", rows)?;
    ctx.set_item("reduced_mass", context.reduced_mass)?;
    Ok(ctx)
}

/// The facts a scenario's (resolved JSON) compensator is built with, as `simulate_python`
/// gives them to `reset(context)`: `period` s, `sensor_delay_ticks`, `sensor_delay` s,
/// `sensor_origin` (`t`, m), `sensor_orientation` [w, x, y, z] and `sensor_rotation` (row-major
/// 3x3), sensor to `t`, `reduced_mass` kg (what a replay of a recording gives a Python
/// compensator). Raises ScenarioError for an invalid scenario.
#[pyfunction]
pub fn compensator_context<'py>(
    py: Python<'py>,
    scenario_json: &str,
) -> PyResult<Bound<'py, PyDict>> {
    context_dict(py, &crate::parse_scenario(py, scenario_json)?)
}
