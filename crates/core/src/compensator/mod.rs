//! Delay compensators: one trait, one file each, picked by a serde-tagged config (`kind`).
//!
//! A compensator runs once per control tick between the sensor and the virtual dynamics.
//! It knows the period, the sensor delay `τ_p` and the sensor origin; it does not know the
//! robot delay, the true stiffness or damping. Its `step` never allocates.

mod none;

pub use none::PassThrough;

use nalgebra::Vector3;
use serde::{Deserialize, Serialize};

use crate::error::Result;
use crate::world::FrameWrench;

/// What a compensator sees at a tick. All vectors in the target frame `t`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CompensatorInput {
    /// Measured wrench on the frame (force N, moment about the sensor origin N·m).
    pub measured: FrameWrench,
    /// Actual contact point (rod tip) from the robot's forward kinematics, eq. (3), m.
    pub tip_position_actual: Vector3<f64>,
    /// Actual contact-point velocity, eq. (4), m/s.
    pub tip_velocity_actual: Vector3<f64>,
    /// Desired contact point from the virtual dynamics, eq. (25), m.
    pub tip_position_desired: Vector3<f64>,
    /// Desired contact-point velocity, eq. (26), m/s.
    pub tip_velocity_desired: Vector3<f64>,
}

/// Identified contact parameters.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ContactEstimate {
    /// Identified stiffness k̂, N/m.
    pub stiffness: f64,
    /// Identified damping ĉ, N·s/m.
    pub damping: f64,
}

/// What a compensator returns at a tick.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CompensatorOutput {
    /// Wrench to apply to the virtual dynamics, same convention as the measurement.
    pub applied: FrameWrench,
    /// Identified contact parameters, if the compensator identifies them.
    pub estimate: Option<ContactEstimate>,
}

/// Fixed facts a compensator may use.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CompensatorContext {
    /// Control period T, s.
    pub period: f64,
    /// Known sensor delay τ_p, s.
    pub sensor_delay: f64,
    /// Sensor origin in `t`, m.
    pub sensor_origin: Vector3<f64>,
}

/// A delay compensator.
pub trait Compensator: Send {
    /// One control tick. Must not allocate, panic, print or read the clock.
    fn step(&mut self, input: &CompensatorInput) -> CompensatorOutput;
    /// Forgets all state (a new run).
    fn reset(&mut self);
    /// Whether `step` returns contact estimates.
    fn estimates_contact(&self) -> bool {
        false
    }
}

/// Which compensator, with its parameters (`[compensator]` in a scenario, tagged by `kind`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, Default)]
#[serde(tag = "kind", rename_all = "kebab-case", deny_unknown_fields)]
pub enum CompensatorConfig {
    /// Pass-through: the measured wrench goes straight into the dynamics (diverges with delay).
    #[default]
    None,
}

impl CompensatorConfig {
    /// The `kind` string.
    pub fn kind(&self) -> &'static str {
        match self {
            CompensatorConfig::None => "none",
        }
    }

    /// Checks the parameters' ranges.
    pub fn validate(&self) -> Result<()> {
        match self {
            CompensatorConfig::None => Ok(()),
        }
    }

    /// Builds the compensator (allocates once, here).
    pub fn build(&self, _context: &CompensatorContext) -> Box<dyn Compensator> {
        match self {
            CompensatorConfig::None => Box::new(PassThrough),
        }
    }
}
