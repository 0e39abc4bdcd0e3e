//! The real-time HIL loop: a sensor link, a robot link, compensator and virtual dynamics in
//! one thread, paced by the PC's monotonic clock at the scenario's period or by the robot's
//! packets ([`crate::devices::Pacing`], the robot link's choice).
//!
//! One tick k (clock pacing: deadline `t0 + k·T`, absolute sleep; robot pacing: the robot's
//! next packet, waited for up to the watchdog):
//! 1. poll the sensor link (non-blocking): the newest valid wrench; poll the robot link: every
//!    valid feedback pose into the [`crate::feedback::FeedbackEstimator`];
//! 2. the measurement: the wrench (sensor frame) and the actual motion estimated from the
//!    feedback ([`crate::feedback`]);
//! 3. `Loop::virtual_step` (`tick.rs`): the core's [`hilcontact_core::hil::HilStep`] (compensate, the record, divergence and
//!    end of run, integrate: the same code as a simulation), the sample into the lock-free
//!    ring buffer, the loop's safety checks ([`crate::safety`]), the new command checked
//!    against the workspace;
//! 4. the command sent through the robot link.
//!
//! The loop names no device: the links ([`crate::devices`]) own the protocols, their counters
//! ([`LinkStats`], socket errors included) and their units. The tick never allocates, locks or
//! logs: sockets are non-blocking, codecs and buffers are preallocated, samples go to an
//! `rtrb` ring buffer that a writer thread drains, counters and the live status are atomics.
//! Lateness is counted, never hidden: every wake-up latency and period goes into a histogram,
//! a tick that ends after the next deadline is an overrun, and missed periods are caught up
//! (the virtual time stays `k·T`).
//!
//! Every stop (end of run, `stop()`, a safety limit) ends the same way: after a force or moment
//! stop the robot first backs away (`hold.rs`), then it is commanded to hold for `hold_time`
//! (its last fed-back pose if plausible, else the last command), the sensor's streaming is
//! stopped, and the writer thread drains the ring buffer completely before the results are
//! built.

//!
//! The files, by what each owns:
//! - `handle.rs`: [`HilHandle`], the run's start (outputs, links, threads), live status, stop
//!   request and end (results built, outputs finished);
//! - `status.rs`: the live status the loop thread publishes ([`StatusSnapshot`]);
//! - `writer.rs`: the writer thread (the ring buffer drained into the run folder and the
//!   outputs of [`crate::output`], the loop's live events);
//! - `start.rs`: the start checks, shared with the dry run ([`crate::check()`]);
//! - `tick.rs`: the loop thread and one tick;
//! - `driver.rs`: the virtual side of a tick ([`driver::Driver`]): the HIL step, or the
//!   calibration procedure (`hilcontact calibrate` over the device links);
//! - `connect.rs`: the loop thread's start-up, before the first tick;
//! - `hold.rs`: the loop thread after a stop (retreat, hold).
//!
//! The options are [`crate::options::RuntimeOptions`].

mod connect;
pub(crate) mod driver;
pub mod handle;
mod hold;
pub(crate) mod start;
pub mod status;
mod tick;
mod writer;

pub use crate::devices::LinkStats;
pub use crate::options::{RuntimeOptions, MAX_CONNECT_TIMEOUT};
pub use crate::report::{RunOutcome, Sample};
pub use handle::HilHandle;
pub(crate) use handle::{LoopEnd, LoopHandle};
pub use status::StatusSnapshot;
pub use tick::CONTACT_FREE_FORCE;
