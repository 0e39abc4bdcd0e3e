//! The virtual side of the HIL loop: compensator and satellite dynamics, and [`HilStep`], the
//! one HIL tick that both the simulation (against a [`crate::facility::Facility`]) and the
//! real-time runtime (against real devices) drive. It reads of the facility only the
//! measurement and the sensor as the plan describes it ([`crate::plan::SensorPlan`]).
//!
//! One control tick k (period T), [`HilStep::observe`] then [`HilStep::advance`]:
//! 1. the facility has advanced to k and reports a [`Measurement`] (sensor wrench, robot motion);
//! 2. the compensator turns it into the wrench to apply ([`VirtualDynamics::compensate`]);
//! 3. the tick's [`HilRecord`] is built and judged: a record that is not finite or whose energy
//!    passed the divergence bound stops the run, and so does the last tick;
//! 4. eqs. (1), (2) advance by T ([`VirtualDynamics::integrate`]); the new command, the relative
//!    motion the robot must reproduce at k+1, must be finite.

use nalgebra::{Matrix3, UnitQuaternion, Vector3};

use crate::compensator::{
    Compensator, CompensatorContext, CompensatorInput, CompensatorOutput, Rendering,
};
use crate::facility::Measurement;
pub use crate::facility::PhysicalContact;
use crate::frames::{FrameWrench, RelativeMotion};
use crate::plan::Plan;
use crate::stop::{Stop, StopKind};
use crate::world::{TwoBodyState, TwoBodySystem};

/// The facts a plan's compensator is built with: period, sensor delay (ticks), sensor origin
/// (`t`, m), reduced mass (kg). The one place they are gathered (live loop and replay).
pub fn compensator_context(plan: &Plan) -> CompensatorContext {
    CompensatorContext {
        period: plan.period,
        sensor_delay_ticks: plan.sensor.delay_ticks,
        sensor_origin: plan.system.sensor_origin,
        reduced_mass: plan.system.reduced_mass(),
        geometry: plan.geometry_prior(),
    }
}

/// Compensator plus virtual satellite dynamics.
pub struct VirtualDynamics {
    system: TwoBodySystem,
    state: TwoBodyState,
    /// The relative motion of `state` (the command), kept with it.
    command: RelativeMotion,
    period: f64,
    /// Sensor attitude in `t` (sensor to `t`).
    sensor_orientation: UnitQuaternion<f64>,
    compensator: Box<dyn Compensator>,
    /// Whether the coming measurement is a new sensor record ([`CompensatorInput::fresh`]).
    sensor_fresh: bool,
    /// Whether the compensator reads the tip's mobility.
    mobility: bool,
}

impl VirtualDynamics {
    /// The virtual side of a plan, at its initial state (allocates the compensator once).
    pub fn new(plan: &Plan) -> Self {
        Self::with_compensator(plan, plan.compensator.build(&compensator_context(plan)))
    }

    /// The virtual side of a plan with a compensator built elsewhere (e.g. one written in
    /// Python, `crates/py`) instead of the plan's `[compensator]`.
    pub fn with_compensator(plan: &Plan, compensator: Box<dyn Compensator>) -> Self {
        let system = &plan.system;
        VirtualDynamics {
            system: system.clone(),
            command: system.relative_motion(&plan.initial),
            state: plan.initial,
            period: plan.period,
            sensor_orientation: plan.sensor.orientation,
            sensor_fresh: true,
            mobility: compensator.uses_tip_mobility(),
            compensator,
        }
    }

    /// Whether the measurements from now on are new sensor records (the default) or the last
    /// one held ([`CompensatorInput::fresh`]): the real-time loop says so at every tick.
    pub fn set_sensor_fresh(&mut self, fresh: bool) {
        self.sensor_fresh = fresh;
    }

    /// The virtual state of both satellites.
    pub fn state(&self) -> &TwoBodyState {
        &self.state
    }

    /// The two-body system.
    pub fn system(&self) -> &TwoBodySystem {
        &self.system
    }

    /// The relative motion the robot must reproduce now (the command).
    pub fn command(&self) -> RelativeMotion {
        self.command
    }

    /// Kinetic energy of the virtual relative motion, J.
    pub fn energy(&self) -> f64 {
        self.system.energy(&self.state)
    }

    /// Whether the compensator identifies contact parameters.
    pub fn estimates_contact(&self) -> bool {
        self.compensator.estimates_contact()
    }

    /// Whether the compensator observes the port energy.
    pub fn observes_energy(&self) -> bool {
        self.compensator.observes_energy()
    }

    /// How the compensator handled the contact of its last step ([`Rendering`]).
    pub fn rendering(&self) -> Rendering {
        self.compensator.rendering()
    }

    /// Runs the compensator on a measurement; the applied wrench is returned in the sensor's
    /// convention (`t` frame inside [`CompensatorOutput`]).
    pub fn compensate(&mut self, m: &Measurement) -> CompensatorOutput {
        self.compensate_input(m).1
    }

    /// [`VirtualDynamics::compensate`], also returning the compensator's input (the rod tips
    /// the tick's record reads, computed once).
    fn compensate_input(&mut self, m: &Measurement) -> (CompensatorInput, CompensatorOutput) {
        let input = self.input(m);
        let output = self.compensator.step(&input);
        (input, output)
    }

    /// What the compensator sees of a measurement at this tick: the wrench turned into `t`,
    /// the actual rod tip (robot) and the desired one (virtual dynamics).
    pub fn input(&self, m: &Measurement) -> CompensatorInput {
        let desired = &self.command;
        let rod = &self.system.rod_tip;
        CompensatorInput {
            measured: FrameWrench {
                force: self.sensor_orientation * m.force,
                moment: self.sensor_orientation * m.moment,
            },
            tip_position_actual: m.actual.point(rod),
            tip_velocity_actual: m.actual.point_velocity(rod),
            orientation_actual: Some(m.actual.orientation),
            tip_position_desired: desired.point(rod),
            tip_velocity_desired: desired.point_velocity(rod),
            motion_desired: Some(*desired),
            tip_mobility: if self.mobility {
                self.system.tip_mobility(&self.state)
            } else {
                Matrix3::zeros()
            },
            fresh: self.sensor_fresh,
        }
    }

    /// Advances the virtual dynamics one period under the compensator's output: its velocity
    /// correction first (an impulse at the rod tip: momentum and angular momentum conserved),
    /// then its wrench (`t` frame) into eqs. (1), (2).
    pub fn integrate(&mut self, output: &CompensatorOutput) {
        self.system
            .correct_tip_velocity(&mut self.state, &output.velocity_correction);
        self.system
            .step_virtual(&mut self.state, &output.applied, self.period);
        self.command = self.system.relative_motion(&self.state);
    }

    /// Sensor attitude in `t`.
    pub fn sensor_orientation(&self) -> UnitQuaternion<f64> {
        self.sensor_orientation
    }
}

/// One tick of the HIL loop, as recorded by simulations and real-time runs alike.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct HilRecord {
    /// Time, s (tick × period).
    pub time: f64,
    /// Desired (virtual) rod tip relative to the target, `t` frame, m.
    pub tip_position: Vector3<f64>,
    /// Desired (virtual) rod tip velocity, `t` frame, m/s.
    pub tip_velocity: Vector3<f64>,
    /// Desired (virtual) angular velocity of the servicer relative to the target, `t`, rad/s.
    pub angular_velocity: Vector3<f64>,
    /// Desired (virtual) attitude of the servicer relative to the target (servicer to `t`);
    /// the rod tip's attitude too, the rod being fixed in the servicer.
    pub orientation: UnitQuaternion<f64>,
    /// Actual (robot) rod tip, `t` frame, m.
    pub actual_tip_position: Vector3<f64>,
    /// Actual (robot) rod tip velocity, `t` frame, m/s.
    pub actual_tip_velocity: Vector3<f64>,
    /// Actual (robot) attitude of the servicer relative to the target (servicer to `t`).
    pub actual_orientation: UnitQuaternion<f64>,
    /// Actual (robot) angular velocity of the servicer relative to the target, `t`, rad/s.
    pub actual_angular_velocity: Vector3<f64>,
    /// Physical contact force on the rod, `t` frame, N (on a real facility, where it is not
    /// observable: the force on the rod that the sensor reports).
    pub contact_force: Vector3<f64>,
    /// Its friction (tangential) part, `t` frame, N (zero on a real facility, which does not
    /// tell the parts apart, and on a frictionless contact).
    pub friction_force: Vector3<f64>,
    /// The physical contact's moment on the frame about the sensor origin, `t`, N·m (on a real
    /// facility, where it is not observable: the sensor's moment).
    pub contact_moment: Vector3<f64>,
    /// Sensor force on the frame, sensor frame, N.
    pub measured_force: Vector3<f64>,
    /// Sensor moment about its origin, sensor frame, N·m.
    pub measured_moment: Vector3<f64>,
    /// Force applied to the virtual dynamics, sensor frame and convention, N.
    pub applied_force: Vector3<f64>,
    /// Moment applied to the virtual dynamics, sensor frame and convention, N·m.
    pub applied_moment: Vector3<f64>,
    /// Kinetic energy of the virtual relative motion, J.
    pub energy: f64,
    /// Identified stiffness, N/m (NaN when not identified).
    pub stiffness_estimate: f64,
    /// Identified damping, N·s/m (NaN when not identified).
    pub damping_estimate: f64,
    /// How many contact laws act in parallel along the physical contact's normal
    /// ([`crate::world::Contact::law_factor`]; NaN where the facility does not know it, as on
    /// a real facility).
    pub law_factor: f64,
    /// Energy observed by the compensator at the environment port, J (NaN when not observed).
    pub observed_energy: f64,
    /// How the compensator handled this tick's contact ([`Rendering::Unreported`] in free
    /// flight and for compensators without a model).
    pub rendering: Rendering,
}

impl HilRecord {
    /// Whether every state and force of the record is finite.
    pub fn is_finite(&self) -> bool {
        let v = [
            self.tip_position,
            self.tip_velocity,
            self.actual_tip_position,
            self.contact_force,
            self.applied_force,
            self.applied_moment,
        ];
        self.energy.is_finite() && v.iter().all(|x| x.iter().all(|c| c.is_finite()))
    }
}

/// The virtual side of one HIL tick, the same for simulations and real-time runs: compensate
/// the measurement, record, judge (divergence, end of run), integrate. Never allocates.
pub struct HilStep {
    virt: VirtualDynamics,
    /// Last tick of the run.
    ticks: usize,
    period: f64,
    /// Energy past which the run is diverged, J.
    energy_bound: f64,
    /// The compensator's output of the tick being run.
    output: CompensatorOutput,
}

impl HilStep {
    /// The step of a plan, with the run's divergence bound (J, see
    /// [`crate::metrics::divergence_bound`]).
    pub fn new(plan: &Plan, energy_bound: f64) -> Self {
        Self::with_dynamics(plan, energy_bound, VirtualDynamics::new(plan))
    }

    /// [`HilStep::new`] with the virtual side given (e.g. [`VirtualDynamics::with_compensator`]).
    pub fn with_dynamics(plan: &Plan, energy_bound: f64, virt: VirtualDynamics) -> Self {
        HilStep {
            virt,
            ticks: plan.ticks,
            period: plan.period,
            energy_bound,
            output: CompensatorOutput::wrench(FrameWrench::default()),
        }
    }

    /// The virtual dynamics (state, command, energy, what the compensator reports).
    pub fn dynamics(&self) -> &VirtualDynamics {
        &self.virt
    }

    /// Whether the coming measurements are new sensor records or the last one held
    /// ([`VirtualDynamics::set_sensor_fresh`]).
    pub fn set_sensor_fresh(&mut self, fresh: bool) {
        self.virt.set_sensor_fresh(fresh);
    }

    /// The relative motion the robot must reproduce now.
    pub fn command(&self) -> RelativeMotion {
        self.virt.command()
    }

    /// Energy past which the run is diverged, J.
    pub fn energy_bound(&self) -> f64 {
        self.energy_bound
    }

    /// Tick `k`'s first half: compensates `m` and returns the tick's record, with the stop it
    /// calls for: [`StopKind::NonFinite`] or [`StopKind::Diverged`] for the record, or
    /// [`StopKind::Completed`] at the last tick. `physical` is the physical contact on the rod
    /// where the facility knows it; `None` on a real facility, where the record keeps the force
    /// on the rod that the sensor reports (and no friction part).
    pub fn observe(
        &mut self,
        k: usize,
        m: &Measurement,
        physical: Option<PhysicalContact>,
    ) -> (HilRecord, Option<Stop>) {
        let (input, out) = self.virt.compensate_input(m);
        self.output = out;
        let sensor_to_t = self.virt.sensor_orientation();
        let desired = self.virt.command();
        let time = k as f64 * self.period;
        let record = HilRecord {
            time,
            tip_position: input.tip_position_desired,
            tip_velocity: input.tip_velocity_desired,
            angular_velocity: desired.angular_velocity,
            orientation: desired.orientation,
            actual_tip_position: input.tip_position_actual,
            actual_tip_velocity: input.tip_velocity_actual,
            actual_orientation: m.actual.orientation,
            actual_angular_velocity: m.actual.angular_velocity,
            contact_force: physical.map_or_else(|| -(sensor_to_t * m.force), |p| p.force),
            friction_force: physical.map_or_else(Vector3::zeros, |p| p.friction_force),
            contact_moment: match physical {
                Some(PhysicalContact {
                    moment: Some(moment),
                    ..
                }) => moment,
                Some(p) => {
                    let tip = &input.tip_position_actual;
                    FrameWrench::from_rod_force(&p.force, tip, &self.virt.system().sensor_origin)
                        .moment
                }
                None => sensor_to_t * m.moment,
            },
            measured_force: m.force,
            measured_moment: m.moment,
            applied_force: sensor_to_t.inverse_transform_vector(&out.applied.force),
            applied_moment: sensor_to_t.inverse_transform_vector(&out.applied.moment),
            energy: self.virt.energy(),
            stiffness_estimate: out.estimate.map_or(f64::NAN, |e| e.stiffness),
            damping_estimate: out.estimate.map_or(f64::NAN, |e| e.damping),
            law_factor: physical.and_then(|p| p.law_factor).unwrap_or(f64::NAN),
            observed_energy: out.observed_energy,
            rendering: self.virt.rendering(),
        };
        let stop = if !record.is_finite() {
            Some(Stop::plain(StopKind::NonFinite, time))
        } else if record.energy > self.energy_bound {
            Some(Stop {
                kind: StopKind::Diverged,
                time,
                value: record.energy,
                limit: self.energy_bound,
            })
        } else if k >= self.ticks {
            Some(Stop::plain(StopKind::Completed, time))
        } else {
            None
        };
        (record, stop)
    }

    /// Tick `k`'s second half: integrates the virtual dynamics one period under the
    /// compensator's output of [`HilStep::observe`] and returns the command for tick k+1, or
    /// a [`StopKind::NonFinite`] stop if it is not finite (never send it to a robot).
    pub fn advance(&mut self, k: usize) -> Result<RelativeMotion, Stop> {
        self.virt.integrate(&self.output);
        let command = self.virt.command();
        let finite = command.position.iter().all(|x| x.is_finite())
            && command.velocity.iter().all(|x| x.is_finite())
            && command.angular_velocity.iter().all(|x| x.is_finite())
            && command.orientation.coords.iter().all(|x| x.is_finite());
        if finite {
            Ok(command)
        } else {
            Err(Stop::plain(StopKind::NonFinite, k as f64 * self.period))
        }
    }
}
