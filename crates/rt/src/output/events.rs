//! The run's events as the outputs get them: their texts and levels, and [`EventWatch`], which
//! turns a real-time loop's live counters and stop into events as the writer thread drains
//! the loop's samples.
//!
//! The events: the start (before the first sample), faults (the loop's counters that grew:
//! lost packets, dropped datagrams, socket errors, overruns; at most one event per
//! [`FAULT_EVENT_INTERVAL_NS`] of run time), the stop as it happens, and at the end the run's
//! status and reason and the loop's summary. The counters' names come from
//! [`crate::counters`].

use serde_json::Value;

use hilcontact_core::metrics::Metrics;

use super::{EventLevel, Outputs, RunInfo};
use crate::counters::{link_summary_text, LoopCounters};
use crate::report::RunOutcome;
use crate::safety::StopKind;

/// The start event's text.
pub fn start_text(info: &RunInfo) -> String {
    format!(
        "{} run of {} started: compensator {}, period {} ms, duration {} s",
        info.kind,
        info.scenario,
        info.compensator,
        info.period * 1e3,
        info.duration
    )
}

/// A simulation's end event (level and text), at run time `end` (s): its status and reason.
pub fn simulation_end(end: f64, metrics: &Metrics) -> (EventLevel, String) {
    let status = serde_json::to_value(metrics.status)
        .ok()
        .and_then(|v| v.as_str().map(str::to_string))
        .unwrap_or_default();
    let level = match status.as_str() {
        "ok" => EventLevel::Info,
        "unfaithful" => EventLevel::Warn,
        _ => EventLevel::Error,
    };
    let text = format!(
        "run ended at {end:.3} s: status {status}; {}",
        metrics
            .reason
            .as_deref()
            .unwrap_or("ran its whole duration")
    );
    (level, text)
}

/// Run time between two fault events, ns: faults that keep coming are summed up, not reported
/// once per tick.
pub const FAULT_EVENT_INTERVAL_NS: u64 = 500_000_000;

/// A real-time run's live events, made by the writer thread after each drain of the loop's
/// samples from the loop's counters and stop.
#[derive(Debug, Default)]
pub struct EventWatch {
    /// The fault counters last reported ([`LoopCounters::faults`]).
    reported: [u64; 5],
    /// Run time of the last fault event, ns.
    last_fault_ns: Option<u64>,
    stop_reported: bool,
}

impl EventWatch {
    /// A watch that has reported nothing.
    pub fn new() -> Self {
        Self::default()
    }

    /// After a drain: a fault event if `counters` grew (at most one per
    /// [`FAULT_EVENT_INTERVAL_NS`] of run time, once the run has started), and the stop once
    /// `stop` is known. Makes nothing (and allocates nothing) when `outputs` is empty.
    pub fn after_drain(
        &mut self,
        outputs: &mut Outputs,
        counters: &LoopCounters,
        stop: Option<StopKind>,
    ) {
        if outputs.is_empty() {
            return;
        }
        let now = outputs.last_time();
        let now_ns = super::time_ns(now);
        let due = self
            .last_fault_ns
            .is_none_or(|t| now_ns >= t + FAULT_EVENT_INTERVAL_NS);
        let faults = counters.faults();
        if outputs.started() && due && faults != self.reported {
            let parts: Vec<String> = LoopCounters::FAULT_NAMES
                .iter()
                .zip(faults.iter().zip(self.reported))
                .filter(|(_, (now, before))| **now > *before)
                .map(|(name, (now, before))| format!("{name} +{} ({now} in all)", now - before))
                .collect();
            outputs.event(now, EventLevel::Warn, &parts.join(", "));
            self.reported = faults;
            self.last_fault_ns = Some(now_ns);
        }
        if let (false, Some(kind)) = (self.stop_reported, stop) {
            self.stop_reported = true;
            let level = match kind {
                StopKind::Completed => EventLevel::Info,
                StopKind::User => EventLevel::Warn,
                _ => EventLevel::Error,
            };
            let name = serde_json::to_value(kind)
                .ok()
                .and_then(|v| v.as_str().map(str::to_string))
                .unwrap_or_default();
            let what = if kind.is_safety_stop() {
                "safety stop"
            } else {
                "stop"
            };
            let now = outputs.last_time();
            outputs.event(
                now,
                level,
                &format!("{what}: {name} at {now:.3} s; the robot is commanded to hold"),
            );
        }
    }
}

/// A real-time run's end events, at the stop's time: the run's status, reason and exit code
/// (from its `metrics`), then the loop's summary (ticks, wake-up latency, overruns, both
/// links' counters).
pub fn realtime_end(outputs: &mut Outputs, outcome: &RunOutcome, metrics: &Value) {
    if outputs.is_empty() {
        return;
    }
    let stop = &outcome.stop;
    let status = metrics["status"].as_str().unwrap_or("?");
    let reason = metrics["reason"]
        .as_str()
        .unwrap_or("ran its whole duration");
    let level = match stop.kind {
        StopKind::Completed if status == "ok" => EventLevel::Info,
        StopKind::Completed | StopKind::User => EventLevel::Warn,
        _ => EventLevel::Error,
    };
    outputs.event(
        stop.time,
        level,
        &format!(
            "run ended at {:.3} s: status {status}; {reason}; exit code {}",
            stop.time,
            stop.kind.exit_code()
        ),
    );
    outputs.event(
        stop.time,
        EventLevel::Info,
        &format!(
            "loop: {} ticks, wake latency p50/p99/max {:.0}/{:.0}/{:.0} µs, overruns {}, samples dropped {}; \
             {} sensor: {}; {} robot: {}",
            outcome.ticks,
            outcome.wake_latency.p50,
            outcome.wake_latency.p99,
            outcome.wake_latency.max,
            outcome.overruns,
            outcome.samples_dropped,
            outcome.sensor_name,
            link_summary_text(&outcome.sensor),
            outcome.robot_name,
            link_summary_text(&outcome.robot),
        ),
    );
}
