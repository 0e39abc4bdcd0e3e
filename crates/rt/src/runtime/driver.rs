//! The virtual side of a tick ([`Driver`]): what turns each tick's measurement into the next
//! command. `hil` drives the loop with the core's [`HilStep`] (compensator and virtual
//! dynamics); `calibrate` with the calibration procedure
//! ([`crate::calibrate::realtime::RealtimeProcedure`]). Every safety function of the loop
//! applies to either's commands unchanged (`tick.rs`).

use hilcontact_core::facility::Measurement;
use hilcontact_core::hil::{HilRecord, HilStep};
use hilcontact_core::world::{RelativeMotion, TwoBodySystem};

use crate::calibrate::realtime::RealtimeProcedure;
use crate::safety::{predicted_wrench, StopEvent};

/// The loop's driver: one method per tick half ([`Driver::observe`], [`Driver::advance`]).
pub(crate) enum Driver {
    /// The HIL run: the core's one HIL step. Never allocates.
    Hil(HilStep),
    /// The calibration procedure over the device links.
    Calibrate(Box<RealtimeProcedure>),
}

impl Driver {
    /// Whether the coming measurements are new sensor records or the last one held.
    pub(crate) fn set_sensor_fresh(&mut self, fresh: bool) {
        match self {
            Driver::Hil(step) => step.set_sensor_fresh(fresh),
            Driver::Calibrate(_) => {}
        }
    }

    /// Tick `k`'s first half: the measurement `m` in; the tick's record and the stop it calls
    /// for (the end of the run or of the procedure, divergence, a non-finite record).
    pub(crate) fn observe(&mut self, k: u64, m: &Measurement) -> (HilRecord, Option<StopEvent>) {
        match self {
            Driver::Hil(step) => step.observe(k as usize, m, None),
            Driver::Calibrate(procedure) => procedure.observe(k, m),
        }
    }

    /// Tick `k`'s second half: the command (relative motion in `t`) for the next tick, or a
    /// non-finite stop (never sent).
    pub(crate) fn advance(&mut self, k: u64) -> Result<RelativeMotion, StopEvent> {
        match self {
            Driver::Hil(step) => step.advance(k as usize),
            Driver::Calibrate(procedure) => procedure.advance(k),
        }
    }

    /// The command the run starts from (the scenario's initial pose, at rest for a
    /// calibration).
    pub(crate) fn command(&self) -> RelativeMotion {
        match self {
            Driver::Hil(step) => step.command(),
            Driver::Calibrate(procedure) => procedure.initial(),
        }
    }

    /// Whether a late tick's missed periods are caught up (the HIL run: its virtual time stays
    /// `k·T`), or skipped (the calibration: a wall's fit may take a long tick, at rest; caught
    /// up, the moves after it would be sent in a burst).
    pub(crate) fn catches_up(&self) -> bool {
        matches!(self, Driver::Hil(_))
    }

    /// The force the units check expects at the robot's fed-back pose `actual`, N: the
    /// scenario's law at the penetration into `system` (the nominal hardware) for the HIL run;
    /// for a calibration, whose premise is that the hardware is not where the scenario says,
    /// the scenario's law at the penetration past the contact its current probe detected (0
    /// before it; the predicted-force line and the procedure's search depth bound the approach).
    pub(crate) fn units_expected(&self, system: &TwoBodySystem, actual: &RelativeMotion) -> f64 {
        match self {
            Driver::Hil(_) => predicted_wrench(system, actual).0,
            Driver::Calibrate(procedure) => procedure.units_expected(actual),
        }
    }

    /// The virtual kinetic energy shown live, J (0 for a calibration: no virtual dynamics).
    pub(crate) fn energy(&self) -> f64 {
        match self {
            Driver::Hil(step) => step.dynamics().energy(),
            Driver::Calibrate(_) => 0.0,
        }
    }
}
