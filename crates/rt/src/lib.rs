//! # hilcontact-rt
//!
//! The real-time side of hilcontact: the HIL loop against a facility over the devices' own
//! network protocols, and an emulated facility that speaks them.
//!
//! - [`rdt`], [`netftapi`]: ATI Net F/T sensor (RDT over UDP, `/netftapi2.xml` over HTTP);
//! - [`sri`]: SRI M812x interface box (AT commands and binary frames over TCP);
//! - [`egm`], [`egm_proto`]: ABB Externally Guided Motion (protobuf over UDP);
//! - [`links`]: the loop's seam to the devices: the [`SensorLink`] and [`RobotLink`] traits,
//!   [`Pacing`], and their RDT, EGM and RSI implementations;
//! - [`rsi`]: KUKA RobotSensorInterface over Ethernet (XML over UDP);
//! - [`mapping`]: the scenario's relative motion (`t` frame, m) as EGM poses (mm, quaternion);
//! - [`emulator`]: robot, contact and sensor (the core's facility model) in real time behind
//!   those protocols;
//! - [`options`]: the real-time options at the edge ([`RuntimeOptions`]) and their JSON Schema;
//! - [`runtime`]: the HIL loop thread (the core's [`hilcontact_core::hil::VirtualDynamics`]) on a
//!   monotonic clock, with [`safety`] limits, a lock-free sample log and timing statistics;
//! - [`recording`]: MCAP recordings of a run (ROS 2 messages, crash-safe chunks) for robotics viewers;
//! - [`report`]: time series and metrics of a real-time run, as a simulation writes them;
//! - [`check`]: a dry run (`hilcontact check`): both links opened as a run opens them, listened
//!   to, and the run's start checks applied, with nothing commanded to the robot.
//!
//! The numerics stay in `hilcontact-core`; this crate owns the I/O, the clocks and the threads.

#![warn(missing_docs)]

pub mod check;
pub mod clock;
pub mod egm;
pub mod egm_proto;
pub mod emulator;
pub mod error;
pub mod feedback;
pub mod links;
pub mod mapping;
pub mod netftapi;
pub mod offset;
pub mod options;
pub mod rdt;
pub mod recording;
pub mod report;
pub mod rsi;
pub mod runtime;
pub mod safety;
pub mod sri;

pub use check::{check, CheckReport};
pub use emulator::{EmulatorOptions, FacilityHandle};
pub use error::{Result, RtError};
pub use links::{LinkStats, Pacing, RobotLink, RobotOptions, SensorLink, SensorOptions};
pub use options::RuntimeOptions;
pub use runtime::HilHandle;
