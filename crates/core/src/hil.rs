//! The virtual side of the HIL loop: compensator and satellite dynamics. The simulation
//! couples it to a [`crate::facility::FacilityModel`]; the real-time runtime will couple the
//! same code to real devices.
//!
//! One control tick k (period T):
//! 1. the facility has advanced to k and reports a [`Measurement`] (sensor wrench, robot motion);
//! 2. [`VirtualDynamics::compensate`] turns it into the wrench to apply;
//! 3. [`VirtualDynamics::integrate`] advances eqs. (1), (2) by T; [`VirtualDynamics::command`]
//!    is the relative motion the robot must reproduce at k+1.

use nalgebra::UnitQuaternion;

use crate::compensator::{Compensator, CompensatorContext, CompensatorInput, CompensatorOutput};
use crate::config::{quaternion, Scenario};
use crate::error::Result;
use crate::facility::Measurement;
use crate::world::{FrameWrench, RelativeMotion, TwoBodyState, TwoBodySystem};

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
}

impl VirtualDynamics {
    /// The virtual side of a (validated) scenario, at its initial state.
    pub fn from_scenario(s: &Scenario, system: &TwoBodySystem) -> Result<Self> {
        let context = CompensatorContext {
            period: s.simulation.period,
            sensor_delay: s.sensor_delay_ticks()? as f64 * s.simulation.period,
            sensor_origin: system.sensor_origin,
            reduced_mass: system.reduced_mass(),
        };
        let state = TwoBodyState::from_scenario(s)?;
        Ok(VirtualDynamics {
            system: system.clone(),
            command: system.relative_motion(&state),
            state,
            period: s.simulation.period,
            sensor_orientation: quaternion(
                "facility.sensor_orientation",
                s.facility.sensor_orientation,
            )?,
            compensator: s.compensator.build(&context),
        })
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

    /// Runs the compensator on a measurement; the applied wrench is returned in the sensor's
    /// convention (`t` frame inside [`CompensatorOutput`]).
    pub fn compensate(&mut self, m: &Measurement) -> CompensatorOutput {
        let input = self.input(m);
        self.compensator.step(&input)
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
            tip_position_desired: desired.point(rod),
            tip_velocity_desired: desired.point_velocity(rod),
        }
    }

    /// Advances the virtual dynamics one period under the compensator's output: its velocity
    /// correction first (momentum conserved), then its wrench (`t` frame) into eqs. (1), (2).
    pub fn integrate(&mut self, output: &CompensatorOutput) {
        self.system
            .correct_relative_velocity(&mut self.state, &output.velocity_correction);
        self.system
            .step_virtual(&mut self.state, &output.applied, self.period);
        self.command = self.system.relative_motion(&self.state);
    }

    /// Sensor attitude in `t`.
    pub fn sensor_orientation(&self) -> UnitQuaternion<f64> {
        self.sensor_orientation
    }
}
