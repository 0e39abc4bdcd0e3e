//! Delay compensators: one trait, one file each, picked by a serde-tagged config (`kind`).
//!
//! A compensator runs once per control tick between the sensor and the virtual dynamics.
//! It knows the period, the sensor delay `τ_p` and the sensor origin; it does not know the
//! robot delay, the true stiffness or damping. Its `step` never allocates.

mod akf;
mod dac;
mod delay;
mod energy;
mod force;
mod none;
mod params;
mod pic;
mod pida;
mod tdpa;

pub use akf::SageHusaFilter;
pub use dac::Dac;
pub use delay::{ContactEstimator, ContactView};
pub use energy::{DampingAmendment, EnergyController, EnergyObserver};
pub use force::{compensate_force, CompensatedWrench};
pub use none::PassThrough;
pub use params::{DelayMode, ModelParams, ObserverMode, TdpaParams};
pub use pic::Pic;
pub use pida::Pida;
pub use tdpa::{TdpaAdmittance, TdpaImpedance};

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
    /// Change of the virtual relative velocity of the servicer, `t` frame, m/s, applied by the
    /// virtual dynamics with momentum conserved (admittance-type compensators act on the
    /// velocity; zero for the others).
    pub velocity_correction: Vector3<f64>,
    /// Identified contact parameters, if the compensator identifies them.
    pub estimate: Option<ContactEstimate>,
    /// Energy observed at the environment port, J (NaN when not observed).
    pub observed_energy: f64,
}

impl CompensatorOutput {
    /// An output that applies `applied` and nothing else.
    pub fn wrench(applied: FrameWrench) -> Self {
        CompensatorOutput {
            applied,
            velocity_correction: Vector3::zeros(),
            estimate: None,
            observed_energy: f64::NAN,
        }
    }
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
    /// Reduced mass of the virtual satellites μ = m_s m_t/(m_s + m_t), kg (the virtual model
    /// is software, so its masses are known).
    pub reduced_mass: f64,
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
    /// Whether `step` returns an observed energy.
    fn observes_energy(&self) -> bool {
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
    /// Algorithm 1: parameter identification control, `F_comp`, `M_comp` into the dynamics.
    Pic(ModelParams),
    /// Algorithm 2: damping amendment control, `F_act + F_α`.
    Dac(ModelParams),
    /// Algorithm 3: identification and damping amendment, `F_comp + F_α`, eqs. (29), (30).
    Pida(ModelParams),
    /// Time-domain passivity, impedance type (a series damper on the force).
    TdpaImpedance(TdpaParams),
    /// Time-domain passivity, admittance type (a damper on the velocity command).
    TdpaAdmittance(TdpaParams),
}

impl CompensatorConfig {
    /// The `kind` string.
    pub fn kind(&self) -> &'static str {
        match self {
            CompensatorConfig::None => "none",
            CompensatorConfig::Pic(_) => "pic",
            CompensatorConfig::Dac(_) => "dac",
            CompensatorConfig::Pida(_) => "pida",
            CompensatorConfig::TdpaImpedance(_) => "tdpa-impedance",
            CompensatorConfig::TdpaAdmittance(_) => "tdpa-admittance",
        }
    }

    /// Checks the parameters' ranges.
    pub fn validate(&self) -> Result<()> {
        match self {
            CompensatorConfig::None => Ok(()),
            CompensatorConfig::Pic(p) | CompensatorConfig::Dac(p) | CompensatorConfig::Pida(p) => {
                p.validate()
            }
            CompensatorConfig::TdpaImpedance(p) | CompensatorConfig::TdpaAdmittance(p) => {
                p.validate()
            }
        }
    }

    /// Builds the compensator (allocates once, here).
    pub fn build(&self, context: &CompensatorContext) -> Box<dyn Compensator> {
        match self {
            CompensatorConfig::None => Box::new(PassThrough),
            CompensatorConfig::Pic(p) => Box::new(Pic::new(p, context)),
            CompensatorConfig::Dac(p) => Box::new(Dac::new(p, context)),
            CompensatorConfig::Pida(p) => Box::new(Pida::new(p, context)),
            CompensatorConfig::TdpaImpedance(p) => Box::new(TdpaImpedance::new(p, context)),
            CompensatorConfig::TdpaAdmittance(p) => Box::new(TdpaAdmittance::new(p, context)),
        }
    }
}
