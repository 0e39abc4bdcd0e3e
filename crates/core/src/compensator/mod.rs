//! Delay compensators: one trait, one file each, picked by a serde-tagged config (`kind`).
//!
//! A compensator runs once per control tick between the sensor and the virtual dynamics.
//! It knows the period, the sensor delay `τ_p` and the sensor origin; it does not know the
//! robot delay, the true stiffness or damping. Its `step` never allocates.

mod akf;
mod dac;
mod delay;
pub mod detect;
mod energy;
mod force;
mod model_mediated;
mod none;
mod params;
mod pic;
mod pida;
pub mod surface;
mod tdpa;

pub use akf::SageHusaFilter;
pub use dac::Dac;
pub use delay::{ContactEstimator, ContactView};
pub use energy::{DampingAmendment, EnergyController, EnergyObserver};
pub use force::{compensate_force, compensate_force_pulling, CompensatedWrench};
pub use model_mediated::{
    fit_contact, frictional_normal, rebound_speed, Fit, ModelMediated, Sample, Surface,
    MAX_SURFACES,
};
pub use none::{NoParams, PassThrough};
pub use params::{
    ControllerMode, DelayMode, LawForm, ModelMediatedParams, ModelParams, ObserverMode,
    PriorShapes, TdpaParams,
};
pub use pic::Pic;
pub use pida::Pida;
pub use tdpa::{TdpaAdmittance, TdpaImpedance};

use nalgebra::{Matrix3, UnitQuaternion, Vector3};
use schemars::JsonSchema;
use serde::{Deserialize, Serialize};

use crate::frames::FrameWrench;

/// What a compensator sees at a tick. All vectors in the target frame `t`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CompensatorInput {
    /// Measured wrench on the frame (force N, moment about the sensor origin N·m).
    pub measured: FrameWrench,
    /// Actual contact point (rod tip) from the robot's forward kinematics, eq. (3), m.
    pub tip_position_actual: Vector3<f64>,
    /// Actual contact-point velocity, eq. (4), m/s.
    pub tip_velocity_actual: Vector3<f64>,
    /// Actual attitude of the servicer relative to the target (servicer to `t`) from the
    /// robot's forward kinematics, as eq. (3)'s tip (`None`: not known, e.g. a recording without
    /// it; the geometry prior then assumes the scenario's initial attitude).
    pub orientation_actual: Option<UnitQuaternion<f64>>,
    /// Desired contact point from the virtual dynamics, eq. (25), m.
    pub tip_position_desired: Vector3<f64>,
    /// Desired contact-point velocity, eq. (26), m/s.
    pub tip_velocity_desired: Vector3<f64>,
    /// The virtual servicer's pose and twist relative to the target (`t`): the motion the
    /// tips above are points of (`None`: not known, e.g. a recording; [`ModelMediated`]'s
    /// shapes prior is then not rendered).
    pub motion_desired: Option<crate::frames::RelativeMotion>,
    /// Mobility `K` of the virtual rod tip, 1/kg: an impulse `J` at the tip changes the desired
    /// tip velocity by `K·J` ([`crate::world::TwoBodySystem::tip_mobility`]); zero unless the
    /// compensator [`Compensator::uses_tip_mobility`].
    pub tip_mobility: Matrix3<f64>,
    /// Whether `measured` is a new sensor record at this tick (`false`: the last record held
    /// because none came, as the real-time loop does on a late sensor). The identifying
    /// compensators learn only from new records and count a held record's age as extra
    /// measurement delay ([`ContactEstimator`]); a simulation's records are all new.
    pub fresh: bool,
}

/// How a compensator that renders contacts from a model handled this tick's contact, and
/// why (`model-mediated`'s per-collision report; every other compensator reports
/// [`Rendering::Unreported`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Rendering {
    /// Nothing to report: free flight, or a compensator without a model.
    #[default]
    Unreported,
    /// Rendered from the model: a modelled surface and a known law.
    Model,
    /// Handled by `pida`: no modelled surface where the force came from.
    PidaNoPrior,
    /// Handled by `pida`: a modelled surface was there, and the contact contradicted it (the
    /// robot felt the surface elsewhere, or not where the model rendered it).
    PidaPriorContradicted,
    /// Handled by `pida`: a modelled surface was there but no contact law is known yet.
    PidaLawUnknown,
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
    /// Change of the virtual rod tip's velocity, `t` frame, m/s, made by the virtual dynamics
    /// with an impulse at the tip, `K⁻¹·Δv` (momentum and angular momentum conserved;
    /// admittance-type compensators act on the velocity; zero for the others).
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
#[derive(Debug, Clone, PartialEq)]
pub struct CompensatorContext {
    /// Control period T, s.
    pub period: f64,
    /// Known sensor delay τ_p, in control ticks.
    pub sensor_delay_ticks: usize,
    /// Sensor origin in `t`, m.
    pub sensor_origin: Vector3<f64>,
    /// Reduced mass of the virtual satellites μ = m_s m_t/(m_s + m_t), kg (the virtual model
    /// is software, so its masses are known).
    pub reduced_mass: f64,
    /// The scenario's nominal contact geometry, the prior for a contact's normal before the
    /// contact's own is fitted ([`crate::world::GeometryPrior`]; `None`: frictionless scenario
    /// or none given). Read-only, its query allocation-free.
    pub geometry: Option<std::sync::Arc<crate::world::GeometryPrior>>,
}

impl CompensatorContext {
    /// Known sensor delay τ_p, s.
    pub fn sensor_delay(&self) -> f64 {
        self.sensor_delay_ticks as f64 * self.period
    }
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
    /// Whether `step` reads the input's `tip_mobility` (computed only then).
    fn uses_tip_mobility(&self) -> bool {
        false
    }
    /// How the contact of the last `step` was handled (no allocation).
    fn rendering(&self) -> Rendering {
        Rendering::Unreported
    }
}

/// One registered compensator kind: what Python, plots and docs learn of it.
#[derive(Debug, Clone, Copy)]
pub struct KindInfo {
    /// The `kind` string of `[compensator]`.
    pub kind: &'static str,
    /// One line for humans (the variant's doc).
    pub summary: &'static str,
    /// Plot colour (a matplotlib colour name).
    pub colour: &'static str,
    /// Its config with default parameters.
    pub default: fn() -> CompensatorConfig,
}

/// Builds the registry from one line per compensator: `Variant = "kind", Params, Type,
/// "colour";` with the variant's doc comment. `Params` implements `Default`, serde and
/// `JsonSchema` (its doc comments give units, its `#[schemars(...)]` attributes the ranges
/// that [`crate::schema::check_ranges`] checks); `Type::new(&Params, &CompensatorContext)`
/// implements [`Compensator`].
macro_rules! registry {
    ($( $(#[doc = $doc:literal])+ $variant:ident = $kind:literal, $params:ty, $imp:ty, $colour:literal; )+) => {
        /// Which compensator, with its parameters (`[compensator]` in a scenario, tagged by
        /// `kind`).
        #[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
        #[serde(tag = "kind", deny_unknown_fields)]
        pub enum CompensatorConfig {
            $( $(#[doc = $doc])+ #[serde(rename = $kind)] $variant($params), )+
        }

        /// Every compensator kind, in the order of the docs and plots: the one list.
        pub const REGISTRY: &[KindInfo] = &[
            $( KindInfo {
                kind: $kind,
                summary: concat!($($doc),+),
                colour: $colour,
                default: || CompensatorConfig::$variant(<$params>::default()),
            }, )+
        ];

        impl CompensatorConfig {
            /// The `kind` string.
            pub fn kind(&self) -> &'static str {
                match self { $( CompensatorConfig::$variant(_) => $kind, )+ }
            }

            /// Builds the compensator (allocates once, here).
            pub fn build(&self, context: &CompensatorContext) -> Box<dyn Compensator> {
                match self { $( CompensatorConfig::$variant(p) => Box::new(<$imp>::new(p, context)), )+ }
            }
        }
    };
}

registry! {
    /// Pass-through: the measured wrench goes straight into the dynamics (diverges with delay).
    None = "none", NoParams, PassThrough, "tab:red";
    /// Algorithm 1: parameter identification control, `F_comp`, `M_comp` into the dynamics.
    Pic = "pic", ModelParams, Pic, "tab:blue";
    /// Algorithm 2: damping amendment control, `F_act + F_α`.
    Dac = "dac", ModelParams, Dac, "tab:orange";
    /// Algorithm 3: identification and damping amendment, `F_comp + F_α`, eqs. (29), (30).
    Pida = "pida", ModelParams, Pida, "tab:green";
    /// Time-domain passivity, impedance type (a series damper on the force).
    TdpaImpedance = "tdpa-impedance", TdpaParams, TdpaImpedance, "tab:purple";
    /// Time-domain passivity, admittance type (a damper on the velocity command).
    TdpaAdmittance = "tdpa-admittance", TdpaParams, TdpaAdmittance, "tab:brown";
    /// Model-mediated rendering: the identified contact (surfaces and law) at the virtual tip; `pida` where the model does not explain a contact.
    ModelMediated = "model-mediated", ModelMediatedParams, ModelMediated, "tab:cyan";
}

impl Default for CompensatorConfig {
    fn default() -> Self {
        CompensatorConfig::None(NoParams)
    }
}

impl CompensatorConfig {
    /// The config of `kind` with default parameters, if `kind` is registered.
    pub fn from_kind(kind: &str) -> Option<Self> {
        REGISTRY
            .iter()
            .find(|k| k.kind == kind)
            .map(|k| (k.default)())
    }
}
