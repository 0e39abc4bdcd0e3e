//! # hilcontact-rt
//!
//! The real-time side of hilcontact: the HIL loop against a facility over the devices' own
//! network protocols, and an emulated facility that speaks them.
//!
//! - [`devices`]: one folder per device protocol, each with its codec, its link (the PC's
//!   side: [`SensorLink`] / [`RobotLink`]), its emulated endpoint (the device's side) and its
//!   options, registered by one line in `devices/mod.rs`: [`devices::rdt`] (ATI Net F/T, RDT
//!   over UDP and `/netftapi2.xml` over HTTP), [`devices::sri`] (SRI M812x, AT commands and
//!   binary frames over TCP), [`devices::egm`] (ABB Externally Guided Motion, protobuf over
//!   UDP), [`devices::rsi`] (KUKA RobotSensorInterface, XML over UDP, robot paced);
//! - [`emulator`]: robot, contact and sensor (the core's facility model) in real time behind
//!   those protocols;
//! - [`options`]: the real-time options at the edge ([`RuntimeOptions`]) and their JSON Schema;
//! - [`runtime`]: the HIL loop thread (the core's [`hilcontact_core::hil::VirtualDynamics`]) on a
//!   monotonic clock, with [`safety`] limits, a lock-free sample log and timing statistics;
//! - [`output`]: the outputs of a run behind one [`output::Sink`] trait, fed by the runtime's
//!   writer thread or from a finished simulation: [`output::mcap`] (MCAP recordings, ROS 2
//!   messages in crash-safe chunks, for robotics viewers) and [`output::run_folder`];
//! - [`counters`]: the links' and the loop's counters shared between threads;
//! - [`report`]: time series and metrics of a real-time run, as a simulation writes them;
//! - [`check`]: a dry run (`hilcontact check`): both links opened as a run opens them, listened
//!   to, and the run's start checks applied, with nothing commanded to the robot.
//!
//! The numerics stay in `hilcontact-core`; this crate owns the I/O, the clocks and the threads.

#![warn(missing_docs)]

pub mod calibrate;
pub mod check;
pub mod clock;
pub mod counters;
pub mod devices;
pub mod emulator;
pub mod error;
pub mod feedback;
pub mod offset;
pub mod options;
pub mod output;
pub mod report;
pub mod runtime;
pub mod safety;

pub use check::{check, CheckReport};
pub use devices::{LinkStats, Pacing, RobotLink, RobotOptions, SensorLink, SensorOptions};
pub use emulator::{EmulatorOptions, FacilityHandle};
pub use error::{Result, RtError};
pub use options::{ReportedUnit, RuntimeOptions};
pub use runtime::HilHandle;
