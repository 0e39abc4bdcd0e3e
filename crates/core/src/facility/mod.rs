//! The facility seam: what stands in for the hardware (robot, mockup, F/T sensor) in a
//! simulation and in the emulated facility of `hilcontact-rt`.
//!
//! - [`Facility`]: the trait every facility engine implements: advance one control period
//!   with the command, measure (the sensor's wrench and the robot's actual motion), and the
//!   physical contact force that a real facility does not report.
//! - [`build`]: the engine of a plan, chosen by `[facility] kind`
//!   ([`crate::config::FacilityKind`]): `"model"`, the facility model
//!   (`facility/model.rs`, [`FacilityModel`]: robot delay and servo lag, the contact law with
//!   the walls, sensor delay, noise and quantisation). `"mujoco"` is an engine written in
//!   Python (`hilcontact.mujoco`): the core cannot build it ([`buildable`] says so); the
//!   bindings run it through [`FacilityLoop::with`] and [`crate::sim::run_hil_against`].
//! - [`FacilityLoop`]: the facility's side of every control tick, the one loop the simulation
//!   ([`crate::sim::run_hil`]) and the emulated facility (`hilcontact_rt::emulator`) run.
//!
//! What the HIL loop itself knows of the sensor (its attitude on the frame, its delay) is the
//! plan's [`crate::plan::SensorPlan`], not an engine's parameters, so that the loop reads the
//! same whatever the engine.
//!
//! Adding an engine: a type implementing [`Facility`] (its own file under `facility/`), a
//! variant of [`crate::config::FacilityKind`] and one arm in [`build`]. Its per-tick methods
//! must not allocate.

mod model;

pub use model::{FacilityModel, RobotModel, SensorModel};

use nalgebra::Vector3;

use crate::config::FacilityKind;
use crate::error::{CoreError, Result};
use crate::frames::RelativeMotion;
use crate::plan::Plan;

/// What the loop receives from the facility at a control tick: the sensor reading and the
/// robot's actual motion (its forward kinematics).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Measurement {
    /// Measured force on the frame, sensor frame, N.
    pub force: Vector3<f64>,
    /// Measured moment about the sensor origin, sensor frame, N·m.
    pub moment: Vector3<f64>,
    /// Actual relative motion of the servicer (robot), `t` frame.
    pub actual: RelativeMotion,
}

/// The physical contact on the rod as a simulated facility knows it (`t` frame, N).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct PhysicalContact {
    /// The whole contact force on the rod, N.
    pub force: Vector3<f64>,
    /// Its friction (tangential) part, N.
    pub friction_force: Vector3<f64>,
    /// The contact's moment on the frame about the sensor origin, `t`, N·m, where the engine
    /// knows it (the shapes' points spread it); `None`: the force's at the rod tip.
    pub moment: Option<Vector3<f64>>,
    /// How many contact laws act in parallel along the contact's normal
    /// ([`crate::world::Contact::law_factor`]: 1 for one point, 0 without contact), where the
    /// engine knows it; `None`: unknown.
    pub law_factor: Option<f64>,
}

/// What stands in for the hardware: a robot that follows the commanded relative motion, the
/// mockup it touches and the F/T sensor between them. One control period is
/// [`Facility::advance`] (except at the first tick) then [`Facility::measure`], as
/// [`FacilityLoop::tick`] runs them. Neither may allocate (they run in the real-time
/// emulator's thread).
pub trait Facility: Send {
    /// Advances one control period (`simulation.period`): the robot receives `command`, the
    /// relative motion of the servicer (`t` frame) it must reproduce at the next tick.
    fn advance(&mut self, command: &RelativeMotion);

    /// The measurement at the current tick: the sensor's wrench (sensor frame, N and N·m)
    /// and the robot's actual motion (`t`). Call it once per tick: it moves the sensor's own
    /// state on (its delay line, its noise generator).
    fn measure(&mut self) -> Measurement;

    /// The physical contact force on the rod at the last [`Facility::measure`], `t` frame, N
    /// (the truth that a real facility does not report: the trace's `contact_force`).
    fn contact_force(&self) -> Vector3<f64>;

    /// The friction (tangential) part of [`Facility::contact_force`], `t` frame, N; an engine
    /// that does not tell the parts apart keeps the default, zero.
    fn friction_force(&self) -> Vector3<f64> {
        Vector3::zeros()
    }

    /// Asks the engine to measure [`PhysicalContact::law_factor`] where that costs extra
    /// (several points of shapes: two more contact evaluations a tick); off until asked. The
    /// simulation asks when the compensator identifies the contact (the identification metric
    /// reads it).
    fn measure_law_factor(&mut self, on: bool) {
        let _ = on;
    }

    /// The physical contact at the last [`Facility::measure`]: the force and its friction part.
    fn physical_contact(&self) -> PhysicalContact {
        PhysicalContact {
            force: self.contact_force(),
            friction_force: self.friction_force(),
            moment: None,
            law_factor: None,
        }
    }
}

/// Whether the core can build the facility engine of a plan ([`build`]): `Err` naming
/// `facility.kind` for an engine written outside the core (`"mujoco"`, a Python engine that
/// `hilcontact` runs through the bindings' `simulate_facility`). Every caller of [`build`]
/// ([`FacilityLoop::new`]) that can refuse checks this first.
pub fn buildable(plan: &Plan) -> Result<()> {
    match plan.facility.kind {
        FacilityKind::Model => Ok(()),
        FacilityKind::Mujoco => Err(CoreError::invalid(
            "facility.kind",
            "\"mujoco\" is an engine written in Python: the core cannot build it; run the \
             scenario with hilcontact (Python: `hilcontact run`/`compare`, \
             `hilcontact.simulate`), which steps MuJoCo (`pip install 'hilcontact[mujoco]'`)",
        )),
    }
}

/// The facility engine of a plan, by `[facility] kind`, with the robot at rest at
/// `initial_command` (the relative motion `t` of the tick 0; its velocities are ignored).
/// Allocates once, here.
///
/// # Panics
/// For a kind the core cannot build ([`buildable`] is `Err`: `"mujoco"`); the entry points
/// that reach here (`sim::simulate`, the bindings, the emulated facility) refuse such a plan
/// with that error first.
pub fn build(plan: &Plan, initial_command: &RelativeMotion) -> Box<dyn Facility> {
    match plan.facility.kind {
        FacilityKind::Model => Box::new(FacilityModel::new(plan, initial_command)),
        FacilityKind::Mujoco => match buildable(plan) {
            Ok(()) => unreachable!("a mujoco facility is never buildable by the core"),
            Err(e) => panic!("{e}"),
        },
    }
}

/// The facility's side of every control tick: tick 0 measures the facility as it starts,
/// each later tick advances it one period with the command for that tick, then measures.
/// The simulation feeds it the new command of every tick; the emulated facility the newest
/// command its robot endpoint received (held until the next). Never allocates.
pub struct FacilityLoop {
    facility: Box<dyn Facility>,
    /// Ticks run so far.
    ticks: u64,
}

impl FacilityLoop {
    /// The loop of a plan's facility ([`build`]), the robot at rest at the plan's initial
    /// relative motion.
    pub fn new(plan: &Plan) -> Self {
        let initial = plan.system.relative_motion(&plan.initial);
        FacilityLoop::with(build(plan, &initial))
    }

    /// The loop around a facility built elsewhere (e.g. an external engine).
    pub fn with(facility: Box<dyn Facility>) -> Self {
        FacilityLoop { facility, ticks: 0 }
    }

    /// Runs one tick: from the second tick on, the facility first advances one period with
    /// `command` (the relative motion `t` the robot must reproduce now: the command issued at
    /// the previous tick); then it is measured. `command` is not read at the first tick.
    pub fn tick(&mut self, command: &RelativeMotion) -> Measurement {
        if self.ticks > 0 {
            self.facility.advance(command);
        }
        self.ticks += 1;
        self.facility.measure()
    }

    /// The physical contact force on the rod at the last tick, `t` frame, N.
    pub fn contact_force(&self) -> Vector3<f64> {
        self.facility.contact_force()
    }

    /// The physical contact on the rod at the last tick (`t` frame): the force and its
    /// friction part.
    pub fn physical_contact(&self) -> PhysicalContact {
        self.facility.physical_contact()
    }

    /// [`Facility::measure_law_factor`] of the facility.
    pub fn measure_law_factor(&mut self, on: bool) {
        self.facility.measure_law_factor(on);
    }

    /// Ticks run so far.
    pub fn ticks(&self) -> u64 {
        self.ticks
    }
}
