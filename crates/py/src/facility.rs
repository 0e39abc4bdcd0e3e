//! A facility engine written in Python in the core's HIL loop (`[facility] kind = "mujoco"`):
//! [`PyFacility`] implements the core's `Facility` trait with the facility model's robot
//! (`RobotModel`: pure delay, optional servo lag) and sensor (`SensorModel`: delay, noise,
//! quantisation), and asks a Python object for the physics of the hardware: the contact between
//! the rod and the mockup for the robot's actual motion (`hilcontact.mujoco.MujocoContact`,
//! MuJoCo). So the robot and the sensor read exactly as the model facility's do, and only the
//! contact comes from the other engine. No numerics here beyond packing numbers.

use std::sync::{Arc, Mutex};

use hilcontact_core::facility::{Facility, FacilityLoop, Measurement, RobotModel, SensorModel};
use hilcontact_core::frames::{FrameWrench, RelativeMotion};
use hilcontact_core::metrics;
use hilcontact_core::sim::{self, hil_table, reference_table};
use hilcontact_core::Plan;
use nalgebra::Vector3;
use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;
use pyo3::types::{PyDict, PyTuple};

/// Numbers handed to the Python engine's `contact_flat` each tick, in this order: the robot's
/// actual relative motion of the servicer in `t`: position (m, 3), attitude quaternion
/// [w, x, y, z] (servicer to `t`, 4), velocity (m/s, 3), angular velocity (`t`, rad/s, 3).
pub const MOTION_LEN: usize = 13;

/// Numbers the Python engine's `contact_flat` returns, in this order: the contact force on the
/// rod (`t`, N, 3), the force on the mockup's frame (`t`, N, 3), its moment about the sensor
/// origin (`t`, N·m, 3), and the friction (tangential) part of the force on the rod (`t`, N, 3).
pub const CONTACT_LEN: usize = 12;

/// The core's `Facility` around a Python contact engine. A failed call (the engine raises or
/// returns something else than [`CONTACT_LEN`] numbers, Ctrl-C) is kept in `fault` and the
/// tick's measurement is non-finite, which stops the run at that tick; the caller then raises
/// the kept error.
struct PyFacility {
    engine: Py<PyAny>,
    robot: RobotModel,
    sensor: SensorModel,
    /// Contact force on the rod at the last measurement, `t`, N.
    contact_force: Vector3<f64>,
    /// Its friction part, `t`, N.
    friction_force: Vector3<f64>,
    fault: Arc<Mutex<Option<PyErr>>>,
}

/// The contact of `engine` for the relative motion `m`: (force on the rod, wrench on the frame,
/// friction part of the force on the rod).
fn contact(
    py: Python<'_>,
    engine: &Py<PyAny>,
    m: &RelativeMotion,
) -> PyResult<(Vector3<f64>, FrameWrench, Vector3<f64>)> {
    let q = m.orientation;
    let mut data = [0.0; MOTION_LEN];
    data[0..3].copy_from_slice(m.position.as_slice());
    data[3..7].copy_from_slice(&[q.w, q.i, q.j, q.k]);
    data[7..10].copy_from_slice(m.velocity.as_slice());
    data[10..13].copy_from_slice(m.angular_velocity.as_slice());
    let args = PyTuple::new(py, data)?;
    let out: Vec<f64> = engine
        .call_method1(py, "contact_flat", (args,))?
        .extract(py)?;
    if out.len() != CONTACT_LEN {
        return Err(PyValueError::new_err(format!(
            "contact_flat: expected {CONTACT_LEN} numbers, got {}",
            out.len()
        )));
    }
    let v = |i: usize| Vector3::new(out[i], out[i + 1], out[i + 2]);
    Ok((
        v(0),
        FrameWrench {
            force: v(3),
            moment: v(6),
        },
        v(9),
    ))
}

impl Facility for PyFacility {
    fn advance(&mut self, command: &RelativeMotion) {
        self.robot.advance(command);
    }

    fn measure(&mut self) -> Measurement {
        let actual = *self.robot.actual();
        let (force_on_rod, wrench, friction) =
            match Python::with_gil(|py| contact(py, &self.engine, &actual)) {
                Ok(result) => result,
                Err(error) => {
                    let mut fault = self.fault.lock().unwrap_or_else(|e| e.into_inner());
                    fault.get_or_insert(error);
                    let nan = Vector3::repeat(f64::NAN);
                    (
                        nan,
                        FrameWrench {
                            force: nan,
                            moment: nan,
                        },
                        nan,
                    )
                }
            };
        self.contact_force = force_on_rod;
        self.friction_force = friction;
        let (force, moment) = self.sensor.sample(&wrench);
        Measurement {
            force,
            moment,
            actual,
        }
    }

    fn contact_force(&self) -> Vector3<f64> {
        self.contact_force
    }

    fn friction_force(&self) -> Vector3<f64> {
        self.friction_force
    }
}

/// Runs a scenario (resolved JSON) against a facility whose contact is computed by `engine`, a
/// Python object with `contact_flat(motion)` (see [`MOTION_LEN`], [`CONTACT_LEN`]; e.g.
/// `hilcontact.mujoco.MujocoContact`), the robot (`facility.robot_delay`, the servo lag) and
/// the sensor (`facility.sensor_delay`, noise, quantisation, `seed`) as the facility model's:
/// the ideal reference, the HIL loop with the scenario's compensator, the metrics (the same
/// functions `simulate` runs). The GIL is released between the engine's calls. Returns what
/// `simulate` returns without outputs (`timeseries`, `reference`, `metrics` as JSON). An error
/// raised by the engine stops the run at that tick and is raised again here.
#[pyfunction]
pub fn simulate_facility<'py>(
    py: Python<'py>,
    scenario_json: &str,
    engine: Py<PyAny>,
) -> PyResult<Bound<'py, PyDict>> {
    let plan: Plan = crate::parse_scenario(py, scenario_json)?;
    let f = &plan.facility;
    let initial = plan.system.relative_motion(&plan.initial);
    let robot = RobotModel::new(
        f.robot_delay_ticks,
        plan.period,
        plan.plant_substeps,
        f.servo_frequency,
        f.servo_damping,
        &initial,
    );
    let (contact_force, initial_wrench, friction_force) = contact(py, &engine, robot.actual())?;
    let fault = Arc::new(Mutex::new(None));
    let facility = PyFacility {
        engine: engine.clone_ref(py),
        sensor: SensorModel::new(&plan, &initial_wrench),
        robot,
        contact_force,
        friction_force,
        fault: fault.clone(),
    };
    let (reference, hil, metrics) = py.allow_threads(|| {
        let (reference_trace, reference) = sim::run_reference(&plan, true);
        let bound = metrics::divergence_bound(
            plan.divergence_energy_ratio,
            reference_trace.energy[0],
            &reference_trace.energy,
        );
        let hil = sim::run_hil_against(&plan, FacilityLoop::with(Box::new(facility)), bound, true);
        let metrics = sim::trace_metrics(
            &plan,
            &reference_trace,
            &hil.trace,
            hil.estimates_contact,
            hil.stop,
        );
        (reference, hil, metrics)
    });
    if let Some(error) = fault.lock().unwrap_or_else(|e| e.into_inner()).take() {
        return Err(error);
    }
    let metrics =
        serde_json::to_string(&metrics).map_err(|e| PyValueError::new_err(e.to_string()))?;
    let result = PyDict::new(py);
    result.set_item(
        "timeseries",
        crate::table_to_dict(
            py,
            hil_table(&hil.rows, hil.estimates_contact, hil.observes_energy),
        )?,
    )?;
    result.set_item(
        "reference",
        crate::table_to_dict(py, reference_table(&reference))?,
    )?;
    result.set_item("metrics", metrics)?;
    Ok(result)
}
