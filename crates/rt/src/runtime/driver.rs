//! The virtual side of a tick ([`Driver`]): what turns each tick's measurement into the next
//! command. `hil` drives the loop with the core's [`HilStep`] (compensator and virtual
//! dynamics); `calibrate` with the calibration procedure (`calibrate::realtime`, which
//! implements this trait: the loop names no driver, so the runtime does not import the
//! calibration). Every safety function of the loop applies to either's commands unchanged
//! (`tick.rs`). The driver is boxed once at start; its calls are the tick's only dynamic
//! dispatch and never allocate for the HIL step.

use std::any::Any;

use hilcontact_core::facility::Measurement;
use hilcontact_core::hil::{HilRecord, HilStep};
use hilcontact_core::world::{RelativeMotion, TwoBodySystem};

use crate::safety::{predicted_wrench, StopEvent};

/// The loop's driver: one method per tick half ([`Driver::observe`], [`Driver::advance`]).
pub(crate) trait Driver: Send {
    /// Whether the coming measurements are new sensor records or the last one held.
    fn set_sensor_fresh(&mut self, _fresh: bool) {}

    /// Whether the coming measurement's pose is a new robot feedback or one held or
    /// extrapolated between the robot's messages (the calibration fits new ones only).
    fn set_robot_fresh(&mut self, _fresh: bool) {}

    /// Tick `k`'s first half: the measurement `m` in; the tick's record and the stop it calls
    /// for (the end of the run or of the procedure, divergence, a non-finite record).
    fn observe(&mut self, k: u64, m: &Measurement) -> (HilRecord, Option<StopEvent>);

    /// Tick `k`'s second half: the command (relative motion in `t`) for the next tick, or a
    /// non-finite stop (never sent).
    fn advance(&mut self, k: u64) -> Result<RelativeMotion, StopEvent>;

    /// The command the run starts from.
    fn command(&self) -> RelativeMotion;

    /// Whether a late tick's missed periods are caught up (the HIL run: its virtual time stays
    /// `k·T`), or skipped.
    fn catches_up(&self) -> bool {
        true
    }

    /// The force the units check expects at the robot's fed-back pose `actual`, N: by default
    /// the scenario's law at the penetration into `system` (the nominal hardware).
    fn units_expected(&self, system: &TwoBodySystem, actual: &RelativeMotion) -> f64 {
        predicted_wrench(system, actual).0
    }

    /// The virtual kinetic energy shown live, J.
    fn energy(&self) -> f64;

    /// The driver as `Any`, for its owner to take it back after the run.
    fn into_any(self: Box<Self>) -> Box<dyn Any + Send>;
}

/// The HIL run: the core's one HIL step. Never allocates.
impl Driver for HilStep {
    fn set_sensor_fresh(&mut self, fresh: bool) {
        HilStep::set_sensor_fresh(self, fresh)
    }

    fn observe(&mut self, k: u64, m: &Measurement) -> (HilRecord, Option<StopEvent>) {
        HilStep::observe(self, k as usize, m, None)
    }

    fn advance(&mut self, k: u64) -> Result<RelativeMotion, StopEvent> {
        HilStep::advance(self, k as usize)
    }

    fn command(&self) -> RelativeMotion {
        HilStep::command(self)
    }

    fn energy(&self) -> f64 {
        self.dynamics().energy()
    }

    fn into_any(self: Box<Self>) -> Box<dyn Any + Send> {
        self
    }
}
