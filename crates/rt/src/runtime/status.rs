//! The loop's live status: `SharedStatus`, the atomics the loop thread publishes each tick
//! (phase, tick, force, energy, latency, overruns, both links' counters through
//! [`SharedLinkStats`], the stop), and [`StatusSnapshot`], what a live display reads of them.

use std::sync::atomic::{AtomicBool, AtomicU64, AtomicU8, Ordering};

use std::sync::Arc;

use serde::Serialize;

use crate::counters::{LoopCounters, SharedLinkStats};
use crate::output::RunControl;
use crate::safety::StopKind;

/// Names of the phases, by their code in [`SharedStatus::phase`].
const PHASES: [&str; 4] = ["connecting", "running", "holding", "finished"];

/// The loop's live state, shared lock-free: the loop thread stores it (each tick), the handle
/// reads it for [`StatusSnapshot`] and `stop()`, the writer thread for the run's events.
#[derive(Debug, Default)]
pub(super) struct SharedStatus {
    pub(super) stop_requested: AtomicBool,
    pub(super) finished: AtomicBool,
    /// 0 connecting, 1 running, 2 holding, 3 finished.
    pub(super) phase: AtomicU8,
    pub(super) stop_code: AtomicU8,
    pub(super) tick: AtomicU64,
    pub(super) force_bits: AtomicU64,
    pub(super) energy_bits: AtomicU64,
    pub(super) max_latency_ns: AtomicU64,
    pub(super) overruns: AtomicU64,
    pub(super) sensor: SharedLinkStats,
    pub(super) robot: SharedLinkStats,
    /// Shared with the outputs: an operator's stop (the live view's).
    pub(super) control: Arc<RunControl>,
}

impl SharedStatus {
    /// What a live display shows, now (`period`: the control period, s).
    pub(super) fn snapshot(&self, period: f64) -> StatusSnapshot {
        let s = self;
        let tick = s.tick.load(Ordering::Relaxed);
        let LoopCounters {
            overruns,
            sensor,
            robot,
        } = s.counters();
        StatusSnapshot {
            phase: PHASES[s.phase.load(Ordering::Acquire).min(3) as usize],
            tick,
            time: tick.saturating_sub(1) as f64 * period,
            force: f64::from_bits(s.force_bits.load(Ordering::Relaxed)),
            energy: f64::from_bits(s.energy_bits.load(Ordering::Relaxed)),
            max_latency_us: s.max_latency_ns.load(Ordering::Relaxed) as f64 / 1e3,
            overruns,
            sensor_lost: sensor.lost,
            sensor_late: sensor.late,
            robot_lost: robot.lost,
            robot_late: robot.late,
            dropped: sensor.dropped() + robot.dropped(),
            io_errors: sensor.io_errors + robot.io_errors,
            stop: StopKind::from_code(s.stop_code.load(Ordering::Acquire)),
        }
    }

    /// The counters the run's events report, as last published.
    pub(super) fn counters(&self) -> LoopCounters {
        LoopCounters {
            overruns: self.overruns.load(Ordering::Relaxed),
            sensor: self.sensor.load(),
            robot: self.robot.load(),
        }
    }
}

/// A snapshot of the loop's state for a live display.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct StatusSnapshot {
    /// `connecting`, `running`, `holding` or `finished`.
    pub phase: &'static str,
    /// Ticks run.
    pub tick: u64,
    /// Virtual time, s.
    pub time: f64,
    /// Measured force magnitude, N.
    pub force: f64,
    /// Virtual kinetic energy, J.
    pub energy: f64,
    /// Largest wake-up latency so far, µs.
    pub max_latency_us: f64,
    /// Ticks that ended after the next deadline.
    pub overruns: u64,
    /// Sensor records lost (sequence gaps).
    pub sensor_lost: u64,
    /// Ticks without a new sensor record.
    pub sensor_late: u64,
    /// Robot feedback messages lost.
    pub robot_lost: u64,
    /// Late robot feedback messages.
    pub robot_late: u64,
    /// Datagrams dropped (malformed, invalid, foreign, stale) on both links.
    pub dropped: u64,
    /// Socket errors (receive or send) on both links.
    pub io_errors: u64,
    /// Why it stopped, once it has.
    pub stop: Option<StopKind>,
}
