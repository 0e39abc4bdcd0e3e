//! A dry run (`hilcontact check`): connects to the sensor and the robot exactly as a run would
//! (the same options, links and [`crate::links::LinkContext`]), listens for a while, and tells
//! whether a run would start, and if not, why, with the same checks as the run's start.
//!
//! Nothing is commanded to the robot, not even a hold: the robot link is only polled (its
//! [`crate::links::RobotLink::send`] and [`crate::links::RobotLink::hold`] are never called). The sensor is asked to
//! stream and to stop, as at a run's start and end.

use std::time::Duration;

use serde::Serialize;

use hilcontact_core::hil::VirtualDynamics;
use hilcontact_core::Scenario;

use crate::clock::now_ns;
use crate::error::{Result, RtError};
use crate::feedback::FeedbackEstimator;
use crate::links::{open_robot, open_sensor, LinkStats, Wrench};
use crate::offset::{OffsetMode, WrenchStats};
use crate::options::MAX_CONNECT_TIMEOUT;
use crate::runtime::{
    check_pacing, check_start_distance, link_context, missing_peers, HilHandle, RuntimeOptions,
};

/// What `hilcontact check` found: both links, and the verdict.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct CheckReport {
    /// The scenario's name.
    pub scenario: String,
    /// How long the links were listened to, s.
    pub duration: f64,
    /// The sensor link.
    pub sensor: SensorCheck,
    /// The robot link.
    pub robot: RobotCheck,
    /// Whether a run with these options would start (`reasons` is empty).
    pub would_start: bool,
    /// Why a run would refuse to start, one message each (the run's own messages).
    pub reasons: Vec<String>,
}

/// The sensor link as the check saw it.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct SensorCheck {
    /// The protocol, e.g. `"RDT"`.
    pub protocol: &'static str,
    /// The peer as the link describes it, e.g. `"the sensor at 127.0.0.1:49152"`.
    pub address: String,
    /// Records accepted per second, from the first to the last arrival, Hz (None: fewer than
    /// two arrivals).
    pub rate: Option<f64>,
    /// The link's counters (received, accepted, malformed, lost, ...).
    pub stats: LinkStats,
    /// What the link reports of the device (RDT: `counts_per_force` per N,
    /// `counts_per_torque` per N·m, `sensor_units`).
    pub report: serde_json::Map<String, serde_json::Value>,
    /// Wrenches averaged for `offset` and `noise` (one per poll that brought a new record).
    pub samples: u64,
    /// The mean wrench, the sensor's offset with the rod free: `[Fx, Fy, Fz]` N then
    /// `[Mx, My, Mz]` N·m, sensor frame (None: no record).
    pub offset: Option<[f64; 6]>,
    /// The standard deviation per axis, the sensor's noise: N then N·m (None: no record).
    pub noise: Option<[f64; 6]>,
    /// The magnitude of the mean force, N (None: no record).
    pub offset_force: Option<f64>,
    /// The magnitude of the mean moment, N·m (None: no record).
    pub offset_moment: Option<f64>,
    /// What a run does with the offset (`measure`: subtracts it, refuses beyond the bounds).
    pub offset_mode: OffsetMode,
    /// Largest force offset a run accepts, N (`offset.max_force`).
    pub offset_max_force: f64,
    /// Largest moment offset a run accepts, N·m (`offset.max_moment`).
    pub offset_max_moment: f64,
}

/// The robot link as the check saw it.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct RobotCheck {
    /// The protocol, e.g. `"EGM"`.
    pub protocol: &'static str,
    /// The link as it describes itself, e.g. `"the robot on UDP port 6510"`.
    pub address: String,
    /// The robot's address the link locked onto, e.g. `"127.0.0.1:40001"` (None: none).
    pub peer: Option<String>,
    /// Feedback messages accepted per second, from the first to the last arrival, Hz (None:
    /// fewer than two arrivals).
    pub rate: Option<f64>,
    /// The link's counters (received, accepted, foreign senders, ...; `sent` stays 0: nothing
    /// is commanded).
    pub stats: LinkStats,
    /// The fed-back rod tip, `t` frame, m (None: no feedback).
    pub rod_tip: Option<[f64; 3]>,
    /// The scenario's initial rod tip, `t` frame, m.
    pub start_rod_tip: [f64; 3],
    /// Distance of the fed-back rod tip from the initial one, m (None: no feedback).
    pub start_distance: Option<f64>,
    /// Largest distance a run accepts, m (`start_tolerance`).
    pub start_tolerance: f64,
}

/// Counts arrivals for a rate: the first and the last time a counter grew, with its value.
#[derive(Debug, Clone, Copy, Default)]
struct RateMeter {
    first: Option<(u64, u64)>,
    last: Option<(u64, u64)>,
}

impl RateMeter {
    /// `count` (accepted so far) seen at `now_ns`.
    fn update(&mut self, now_ns: u64, count: u64) {
        if count == 0 || self.last.is_some_and(|(_, c)| c == count) {
            return;
        }
        if self.first.is_none() {
            self.first = Some((now_ns, count));
        }
        self.last = Some((now_ns, count));
    }

    /// Arrivals per second between the first and the last, Hz.
    fn hz(&self) -> Option<f64> {
        let ((t0, c0), (t1, c1)) = (self.first?, self.last?);
        (t1 > t0).then(|| (c1 - c0) as f64 / ((t1 - t0) as f64 * 1e-9))
    }
}

fn six(w: &Wrench) -> [f64; 6] {
    [
        w.force.x, w.force.y, w.force.z, w.moment.x, w.moment.y, w.moment.z,
    ]
}

/// Checks that a run of `scenario` with `options` would start, commanding nothing: opens the
/// links as [`HilHandle::start`] does, asks the sensor to stream, listens to both links for
/// `duration` s, stops the streaming, and applies the run's start checks to what arrived (a
/// record and feedback, the start distance, the offset, the scenario's start in contact with
/// `offset.mode = measure`, the robot's pacing).
///
/// Errors are bad input (scenario, options, `duration`) and links that cannot be opened (a
/// port in use, the sensor's counts per unit unreadable); everything else is in the report.
pub fn check(scenario: &Scenario, options: &RuntimeOptions, duration: f64) -> Result<CheckReport> {
    let (plan, parsed) = HilHandle::validate_options(scenario, options)?;
    if !(duration.is_finite() && duration > 0.0 && duration <= MAX_CONNECT_TIMEOUT) {
        return Err(RtError::option(
            "duration",
            format!("must be a number of seconds > 0 and <= {MAX_CONNECT_TIMEOUT}, got {duration}"),
        ));
    }
    let context = link_context(&plan, options);
    let mut sensor = open_sensor(&parsed.sensor, &context)?;
    let mut robot = open_robot(&parsed.robot, &context)?;
    let mut estimator = FeedbackEstimator::new(options.extrapolation);
    let mut wrenches = WrenchStats::default();
    let (mut sensor_rate, mut robot_rate) = (RateMeter::default(), RateMeter::default());

    // listen (nothing is sent to the robot)
    sensor.start_streaming();
    let start = now_ns();
    let end = start + (duration * 1e9) as u64;
    let mut last_request = start;
    loop {
        let now = now_ns();
        if now >= end {
            break;
        }
        if let Some(w) = sensor.poll(now) {
            wrenches.push(&w);
        }
        robot.poll(now, &mut estimator);
        sensor_rate.update(now, sensor.stats().accepted);
        robot_rate.update(now, robot.stats().accepted);
        if sensor.stats().accepted == 0 && now - last_request > 200_000_000 {
            sensor.start_streaming();
            last_request = now;
        }
        std::thread::sleep(Duration::from_millis(1));
    }
    sensor.stop_streaming();

    // the run's start checks, in the run's order
    let mut reasons = Vec::new();
    let offset_measurable = match options.offset.check_start(&plan) {
        Ok(()) => true,
        Err(e) => {
            reasons.push(e.to_string());
            false
        }
    };
    if let Err(e) = check_pacing(robot.as_ref(), plan.period) {
        reasons.push(e.to_string());
    }
    reasons.extend(missing_peers(
        sensor.as_ref(),
        robot.as_ref(),
        estimator.has_feedback(),
    ));
    let initial = VirtualDynamics::new(&plan).command();
    let rod = plan.system.rod_tip;
    let start_tip = initial.point(&rod);
    let tip = estimator.last_pose().map(|p| p.point(&rod));
    let start_distance = tip.map(|t| (t - start_tip).norm());
    if let Some(d) = start_distance {
        if let Err(e) = check_start_distance(d, options.start_tolerance) {
            reasons.push(e.to_string());
        }
    }
    let has_record = wrenches.count() > 0;
    if has_record && offset_measurable && options.offset.mode == OffsetMode::Measure {
        if let Err(e) = options.offset.offset(&wrenches) {
            reasons.push(e.to_string());
        }
    }

    let (mean, std) = (wrenches.mean(), wrenches.std());
    Ok(CheckReport {
        scenario: plan.scenario.name.clone(),
        duration,
        sensor: SensorCheck {
            protocol: sensor.name(),
            address: sensor.describe(),
            rate: sensor_rate.hz(),
            stats: *sensor.stats(),
            report: sensor.report(),
            samples: wrenches.count(),
            offset: has_record.then(|| six(&mean)),
            noise: has_record.then(|| six(&std)),
            offset_force: has_record.then(|| mean.force.norm()),
            offset_moment: has_record.then(|| mean.moment.norm()),
            offset_mode: options.offset.mode,
            offset_max_force: options.offset.max_force,
            offset_max_moment: options.offset.max_moment,
        },
        robot: RobotCheck {
            protocol: robot.name(),
            address: robot.describe(),
            peer: robot.peer().map(|a| a.to_string()),
            rate: robot_rate.hz(),
            stats: *robot.stats(),
            rod_tip: tip.map(|t| [t.x, t.y, t.z]),
            start_rod_tip: [start_tip.x, start_tip.y, start_tip.z],
            start_distance,
            start_tolerance: options.start_tolerance,
        },
        would_start: reasons.is_empty(),
        reasons,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_rate_counts_arrivals_between_the_first_and_the_last() {
        let mut r = RateMeter::default();
        assert_eq!(r.hz(), None);
        r.update(0, 0);
        r.update(1_000_000, 3);
        assert_eq!(r.hz(), None);
        r.update(2_000_000, 3); // nothing new
        r.update(11_000_000, 13);
        assert!((r.hz().unwrap() - 1000.0).abs() < 1e-9);
    }
}
