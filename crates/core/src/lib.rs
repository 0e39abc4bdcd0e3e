//! # hilcontact-core
//!
//! Numerical core of hilcontact: hardware-in-the-loop (HIL) simulation of satellite contact
//! on an industrial-robot facility, after He & Shen, IEEE Access 2022 (equation numbers in
//! doc comments are the paper's).
//!
//! No Python, no I/O, no clock: the per-tick step functions ([`facility::FacilityModel`],
//! [`hil::VirtualDynamics`], [`compensator::Compensator`]) never allocate, so the real-time
//! runtime runs the same code as the simulation.
//!
//! Conventions: SI units; the target body frame is the mockup frame `t`; a wall's normal
//! points into free space; the contact force on the rod is `max(0, k·d + c·ḋ)·n`; the sensor
//! measures the opposite force on the frame with its moment about the sensor origin;
//! time is `tick × period`.

pub mod body;
pub mod calibration;
pub mod compensator;
pub mod config;
pub mod contact;
pub mod delay_line;
pub mod error;
pub mod facility;
pub mod frames;
pub mod hil;
pub mod identify;
pub mod metrics;
pub mod plan;
pub mod replay;
pub mod schema;
pub mod shapes;
pub mod sim;
pub mod stop;
pub mod sweep;
pub mod world;

pub use config::Scenario;
pub use error::{CoreError, RecordingError, Result, ScenarioIssue};
pub use plan::Plan;
pub use sim::{simulate, simulate_metrics, SimulationOutput, Table};
