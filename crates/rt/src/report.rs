//! The results of a real-time run in the simulation's format: the time series (same columns,
//! plus the loop's timing), the ideal reference and the metrics (the core's definitions in
//! [`hilcontact_core::metrics`]), with a `realtime` section of timing and packet statistics.
//!
//! In a real-time run the physical contact force is not observable: `contact_force_*` is the
//! force on the rod that the sensor reports (the opposite of the measured force, rotated into
//! `t`), so it carries the sensor's delay and noise; collisions, CoF and the identification
//! error are computed from it.

use serde_json::{json, Value};

use hilcontact_core::hil::VirtualDynamics;
use hilcontact_core::metrics::Metrics;
use hilcontact_core::sim::{
    hil_table, hil_trace, reference_table, run_reference, scalar, table, trace_metrics, Field,
    HilRecord, Table,
};
use hilcontact_core::Plan;

use std::net::SocketAddr;

use crate::clock::{SchedulingReport, TimingSummary};
use crate::devices::{LinkStats, Pacing};
use crate::error::{Result, RtError};
use crate::safety::{SafetyReport, StopEvent};

/// One tick of the loop, as logged (fixed size, `Copy`): the simulation's record of a tick
/// plus the loop's timing.
///
/// In the record, `time` is the virtual time (tick × period), `actual_*` the rod tip estimated
/// from EGM feedback and `contact_force` the force on the rod that the sensor reports (the
/// opposite of the measured force, in `t`): the true contact force is not observable.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Sample {
    /// The tick, as the simulation records it.
    pub record: HilRecord,
    /// Wake-up latency of the tick, s.
    pub wake_latency: f64,
    /// Age of the sensor record used (since its arrival), s.
    pub sensor_age: f64,
    /// Age of the newest robot feedback (since its arrival), s.
    pub robot_age: f64,
}

/// What the loop thread hands back.
#[derive(Debug, Clone)]
pub struct RunOutcome {
    /// Why it stopped.
    pub stop: StopEvent,
    /// Ticks run.
    pub ticks: u64,
    /// Wall time of the loop, s.
    pub wall_time: f64,
    /// Wake-up latency (wake − deadline), µs.
    pub wake_latency: TimingSummary,
    /// |actual period − T|, µs.
    pub period_error: TimingSummary,
    /// Time from wake-up to the command sent, µs.
    pub compute: TimingSummary,
    /// Ticks that ended after the next deadline.
    pub overruns: u64,
    /// Sensor link.
    pub sensor: LinkStats,
    /// Robot link.
    pub robot: LinkStats,
    /// Commands sent to the robot.
    pub commands_sent: u64,
    /// Commands that could not be sent.
    pub send_errors: u64,
    /// Samples lost because the ring buffer was full.
    pub samples_dropped: u64,
    /// The sensor link's protocol name (e.g. `RDT`).
    pub sensor_name: &'static str,
    /// The robot link's protocol name (e.g. `EGM`).
    pub robot_name: &'static str,
    /// What clocked the loop.
    pub pacing: Pacing,
    /// The sensor link's own facts for the metrics (e.g. counts per unit).
    pub sensor_report: serde_json::Map<String, serde_json::Value>,
    /// The robot link's own facts for the metrics (e.g. RSI's answer latency).
    pub robot_report: serde_json::Map<String, serde_json::Value>,
    /// The robot's address.
    pub robot_address: Option<SocketAddr>,
    /// The sensor's offset measured at start and subtracted from every record, `[Fx, Fy, Fz]`
    /// N then `[Mx, My, Mz]` N·m (None: `bias.mode = "off"`).
    pub sensor_offset: Option<[f64; 6]>,
    /// What the OS granted the loop thread: policy, priority, locked memory, CPU.
    pub scheduling: SchedulingReport,
    /// What the safety functions saw: predicted and measured peaks, the limit line that
    /// tripped, the robot's measured cycle, the units check.
    pub safety: SafetyReport,
}

/// Everything a real-time run produces.
#[derive(Debug, Clone)]
pub struct HilOutput {
    /// One row per tick: the simulation's columns plus `wake_latency`, `sensor_age`,
    /// `robot_age` (s).
    pub timeseries: Table,
    /// The ideal reference over the scenario's duration.
    pub reference: Table,
    /// `metrics.json`: a [`RealtimeMetrics`] as JSON.
    pub metrics: Value,
    /// Exit code of the `hil` command (0, 3 safety stop, 130 user stop).
    pub exit_code: i32,
}

/// `metrics.json` of a real-time run: the core's metrics (status, reason, `diverged_at` and
/// `stop` from the run's stop, as for a simulation) and the loop's timing and packet
/// statistics.
#[derive(Debug, Clone, serde::Serialize)]
pub struct RealtimeMetrics {
    /// The metrics of the run, as a simulation computes them.
    #[serde(flatten)]
    pub core: Metrics,
    /// Timing, packet counters, links, the loop thread's scheduling, options.
    pub realtime: Value,
}

/// The time-series columns a real-time run adds to the HIL loop's: the tick's wake-up latency,
/// and the age of the sensor record and of the robot feedback it used.
pub const REALTIME_FIELDS: [Field<Sample>; 3] = [
    scalar("wake_latency", "s", |s| s.wake_latency),
    scalar("sensor_age", "s", |s| s.sensor_age),
    scalar("robot_age", "s", |s| s.robot_age),
];

/// The loop's report of a run (`realtime` in `metrics.json`, and a calibration's): its
/// period (s), ticks, `samples` kept, wall time (s), the stop (with `reason` and the command's
/// `exit_code`), the timing statistics (µs), the links' counters and own facts (RDT:
/// counts_per_force, counts_per_torque, sensor_units; RSI: rsi), the pacing, the sensor's
/// offset, the loop thread's scheduling, the safety functions' report and the `options`.
pub fn loop_report(
    outcome: &RunOutcome,
    period: f64,
    samples: usize,
    reason: Option<String>,
    exit_code: i32,
    options: &impl serde::Serialize,
) -> Value {
    let stop = &outcome.stop;
    let finite = |v: f64| if v.is_finite() { json!(v) } else { Value::Null };
    let mut realtime = json!({
        "period": period,
        "ticks": outcome.ticks,
        "samples": samples,
        "wall_time": outcome.wall_time,
        "stop": {
            "kind": stop.kind,
            "reason": reason,
            "time": stop.time,
            "value": finite(stop.value),
            "limit": finite(stop.limit),
            "safety_stop": stop.kind.is_safety_stop(),
            "exit_code": exit_code,
        },
        "timing": {
            "wake_latency_us": outcome.wake_latency,
            "period_error_us": outcome.period_error,
            "compute_us": outcome.compute,
            "overruns": outcome.overruns,
        },
        "sensor": outcome.sensor,
        "robot": outcome.robot,
        "commands_sent": outcome.commands_sent,
        "send_errors": outcome.send_errors,
        "samples_dropped": outcome.samples_dropped,
        "pacing": outcome.pacing,
        "robot_address": outcome.robot_address.map(|a| a.to_string()),
        "sensor_offset": outcome.sensor_offset,
        "scheduling": outcome.scheduling,
        "safety": outcome.safety,
        "options": options,
    });
    if let Some(section) = realtime.as_object_mut() {
        for (key, value) in outcome.sensor_report.iter().chain(&outcome.robot_report) {
            section.insert(key.clone(), value.clone());
        }
    }
    realtime
}

/// Builds the output of a run from its samples.
pub fn build_output(
    plan: &Plan,
    options: &impl serde::Serialize,
    samples: &[Sample],
    outcome: &RunOutcome,
) -> Result<HilOutput> {
    let virt = VirtualDynamics::new(plan);
    let (estimates, observes) = (virt.estimates_contact(), virt.observes_energy());
    let records: Vec<HilRecord> = samples.iter().map(|s| s.record).collect();
    let mut timeseries = hil_table(&records, estimates, observes);
    timeseries
        .columns
        .extend(table(samples, &REALTIME_FIELDS, |_| true).columns);

    let (reference_trace, reference) = run_reference(plan, true);
    let trace = hil_trace(plan, &records, estimates);
    let stop = &outcome.stop;
    let mut core = trace_metrics(plan, &reference_trace, &trace, estimates, *stop);
    // a stop's reason names the links' protocols ("no valid RDT record"); a run that ran to
    // its end keeps the verdict's reason (none, or why it is unfaithful)
    if let Some(reason) = stop.reason_naming(outcome.sensor_name, outcome.robot_name) {
        core.reason = Some(reason);
    }
    let realtime = loop_report(
        outcome,
        plan.period,
        samples.len(),
        core.reason.clone(),
        stop.kind.exit_code(),
        options,
    );
    let metrics = serde_json::to_value(RealtimeMetrics { core, realtime })
        .map_err(|e| RtError::io_other("metrics", e.to_string()))?;
    Ok(HilOutput {
        timeseries,
        reference: reference_table(&reference),
        metrics,
        exit_code: stop.kind.exit_code(),
    })
}
