//! The results of a real-time run in the simulation's format: the time series (same columns,
//! plus the loop's timing), the ideal reference and the metrics (the core's definitions in
//! [`hilcontact_core::metrics`]), with a `realtime` section of timing and packet statistics.
//!
//! In a real-time run the physical contact force is not observable: `contact_force_*` is the
//! force on the rod that the sensor reports (the opposite of the measured force, rotated into
//! `t`), so it carries the sensor's delay and noise; collisions, CoF and the identification
//! error are computed from it.

use nalgebra::Vector3;
use serde_json::{json, Value};

use hilcontact_core::hil::VirtualDynamics;
use hilcontact_core::metrics::Status;
use hilcontact_core::sim::{reference_table, run_reference, trace_metrics, Table, Trace};
use hilcontact_core::world::TwoBodySystem;
use hilcontact_core::Scenario;

use crate::error::{Result, RtError};
use crate::runtime::{RunOutcome, RuntimeOptions, Sample};

/// Everything a real-time run produces.
#[derive(Debug, Clone)]
pub struct HilOutput {
    /// One row per tick: the simulation's columns plus `wake_latency`, `sensor_age`,
    /// `robot_age` (s).
    pub timeseries: Table,
    /// The ideal reference over the scenario's duration.
    pub reference: Table,
    /// `metrics.json`, with its `realtime` section.
    pub metrics: Value,
    /// Exit code of the `hil` command (0, 3 safety stop, 130 user stop).
    pub exit_code: i32,
}

fn push_vector<R>(
    columns: &mut Vec<(String, Vec<f64>)>,
    rows: &[R],
    name: &str,
    get: impl Fn(&R) -> Vector3<f64>,
) {
    for (axis, label) in ["x", "y", "z"].iter().enumerate() {
        columns.push((
            format!("{name}_{label}"),
            rows.iter().map(|r| get(r)[axis]).collect(),
        ));
    }
}

fn push_scalar<R>(
    columns: &mut Vec<(String, Vec<f64>)>,
    rows: &[R],
    name: &str,
    get: impl Fn(&R) -> f64,
) {
    columns.push((name.to_string(), rows.iter().map(get).collect()));
}

/// Builds the output of a run from its samples.
pub fn build_output(
    scenario: &Scenario,
    system: &TwoBodySystem,
    options: &RuntimeOptions,
    samples: &[Sample],
    outcome: &RunOutcome,
) -> Result<HilOutput> {
    let virt = VirtualDynamics::from_scenario(scenario, system)?;
    let (estimates, observes) = (virt.estimates_contact(), virt.observes_energy());
    let mut columns = Vec::new();
    push_scalar(&mut columns, samples, "time", |s| s.time);
    push_vector(&mut columns, samples, "tip_position", |s| s.tip_position);
    push_vector(&mut columns, samples, "tip_velocity", |s| s.tip_velocity);
    push_vector(&mut columns, samples, "actual_tip_position", |s| {
        s.actual_tip_position
    });
    push_vector(&mut columns, samples, "actual_tip_velocity", |s| {
        s.actual_tip_velocity
    });
    push_vector(&mut columns, samples, "contact_force", |s| s.contact_force);
    push_vector(&mut columns, samples, "measured_force", |s| {
        s.measured_force
    });
    push_vector(&mut columns, samples, "measured_moment", |s| {
        s.measured_moment
    });
    push_vector(&mut columns, samples, "applied_force", |s| s.applied_force);
    push_vector(&mut columns, samples, "applied_moment", |s| {
        s.applied_moment
    });
    push_scalar(&mut columns, samples, "energy", |s| s.energy);
    if estimates {
        push_scalar(&mut columns, samples, "stiffness_estimate", |s| {
            s.stiffness_estimate
        });
        push_scalar(&mut columns, samples, "damping_estimate", |s| {
            s.damping_estimate
        });
    }
    if observes {
        push_scalar(&mut columns, samples, "observed_energy", |s| {
            s.observed_energy
        });
    }
    push_scalar(&mut columns, samples, "wake_latency", |s| s.wake_latency);
    push_scalar(&mut columns, samples, "sensor_age", |s| s.sensor_age);
    push_scalar(&mut columns, samples, "robot_age", |s| s.robot_age);
    let timeseries = Table { columns };

    let (reference_trace, reference) = run_reference(scenario, system, true)?;
    let trace = Trace {
        time: samples.iter().map(|s| s.time).collect(),
        force: samples.iter().map(|s| s.contact_force.norm()).collect(),
        speed: samples.iter().map(|s| s.tip_velocity.norm()).collect(),
        energy: samples.iter().map(|s| s.energy).collect(),
        stiffness_estimate: samples.iter().map(|s| s.stiffness_estimate).collect(),
        damping_estimate: samples.iter().map(|s| s.damping_estimate).collect(),
    };
    // status and reason are the runtime's, set below
    let core_metrics = trace_metrics(
        scenario,
        &reference_trace,
        &trace,
        estimates,
        Status::Ok,
        None,
    );
    let mut metrics =
        serde_json::to_value(&core_metrics).map_err(|e| RtError::Io(format!("metrics: {e}")))?;
    let stop = &outcome.stop;
    let finite = |v: f64| if v.is_finite() { json!(v) } else { Value::Null };
    metrics["status"] = json!(stop.kind.status());
    metrics["reason"] = stop.reason().map_or(Value::Null, Value::from);
    metrics["diverged_at"] = if stop.kind == crate::safety::StopKind::Diverged {
        json!(stop.time)
    } else {
        Value::Null
    };
    metrics["realtime"] = json!({
        "period": scenario.simulation.period,
        "ticks": outcome.ticks,
        "samples": samples.len(),
        "wall_time": outcome.wall_time,
        "stop": {
            "kind": stop.kind,
            "reason": stop.reason(),
            "time": stop.time,
            "value": finite(stop.value),
            "limit": finite(stop.limit),
            "safety_stop": stop.kind.is_safety_stop(),
            "exit_code": stop.kind.exit_code(),
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
        "counts_per_force": outcome.counts.force,
        "counts_per_torque": outcome.counts.torque,
        "robot_address": outcome.robot_address.map(|a| a.to_string()),
        "options": options,
    });
    Ok(HilOutput {
        timeseries,
        reference: reference_table(&reference),
        metrics,
        exit_code: stop.kind.exit_code(),
    })
}
