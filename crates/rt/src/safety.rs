//! Safety limits of the real-time loop and the reasons a run stops.
//!
//! Every tick the loop checks, in this order: a user stop; the watchdogs (no valid sensor
//! record / robot feedback for `watchdog_ms`); the force and moment limits on the measured
//! wrench (magnitudes, sensor frame); then, on the new command, that it is finite and that
//! the commanded rod tip stays within `workspace` metres of where it started; and that the
//! virtual energy stays below the scenario's divergence bound. Any of them stops the run:
//! the robot is commanded to hold its last fed-back pose, sensor streaming is stopped, the
//! sample log is drained, and the [`StopKind`] goes to `metrics.json` and the exit code.

use nalgebra::Vector3;
use serde::{Deserialize, Serialize};

use crate::error::{Result, RtError};

/// The limits, with units. Defaults: 500 N, 100 N·m, 50 ms, 0.1 m.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct SafetyLimits {
    /// Largest measured force magnitude, N (> 0).
    pub force_limit: f64,
    /// Largest measured moment magnitude about the sensor origin, N·m (> 0).
    pub moment_limit: f64,
    /// Longest time without a valid sensor record or robot feedback, ms (> 0).
    pub watchdog_ms: f64,
    /// Largest distance of the commanded rod tip from its initial position, m (> 0).
    pub workspace: f64,
}

impl Default for SafetyLimits {
    fn default() -> Self {
        SafetyLimits {
            force_limit: 500.0,
            moment_limit: 100.0,
            watchdog_ms: 50.0,
            workspace: 0.1,
        }
    }
}

impl SafetyLimits {
    /// Checks that every limit is a positive number.
    pub fn validate(&self) -> Result<()> {
        for (key, v) in [
            ("force_limit", self.force_limit),
            ("moment_limit", self.moment_limit),
            ("watchdog_ms", self.watchdog_ms),
            ("workspace", self.workspace),
        ] {
            if !(v.is_finite() && v > 0.0) {
                return Err(RtError::option(
                    key,
                    format!("must be a positive number, got {v}"),
                ));
            }
        }
        Ok(())
    }

    /// The watchdog in ns.
    pub fn watchdog_ns(&self) -> u64 {
        (self.watchdog_ms * 1e6) as u64
    }
}

/// Why a run stopped.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum StopKind {
    /// Ran for the whole duration.
    Completed,
    /// `stop()` was called (Ctrl-C).
    User,
    /// Measured force magnitude above the limit.
    ForceLimit,
    /// Measured moment magnitude above the limit.
    MomentLimit,
    /// No valid sensor record for longer than the watchdog.
    SensorWatchdog,
    /// No valid robot feedback for longer than the watchdog.
    RobotWatchdog,
    /// Commanded rod tip outside the workspace.
    Workspace,
    /// The command stopped being finite.
    NonFinite,
    /// The virtual energy passed the scenario's divergence bound.
    Diverged,
}

impl StopKind {
    /// Whether a safety function stopped the run.
    pub fn is_safety_stop(self) -> bool {
        !matches!(self, StopKind::Completed | StopKind::User)
    }

    /// Exit code of the `hilcontact hil` command: 0 completed, 130 user stop (Ctrl-C),
    /// 3 any safety stop.
    pub fn exit_code(self) -> i32 {
        match self {
            StopKind::Completed => 0,
            StopKind::User => 130,
            _ => 3,
        }
    }

    /// The status written to `metrics.json`: `ok`, `interrupted`, `diverged` or `stopped`.
    pub fn status(self) -> &'static str {
        match self {
            StopKind::Completed => "ok",
            StopKind::User => "interrupted",
            StopKind::Diverged => "diverged",
            _ => "stopped",
        }
    }

    /// Small integer for the status atomics (0 = still running).
    pub fn code(self) -> u8 {
        self as u8 + 1
    }

    /// The kind of a [`StopKind::code`].
    pub fn from_code(code: u8) -> Option<Self> {
        use StopKind::*;
        [
            Completed,
            User,
            ForceLimit,
            MomentLimit,
            SensorWatchdog,
            RobotWatchdog,
            Workspace,
            NonFinite,
            Diverged,
        ]
        .get((code as usize).checked_sub(1)?)
        .copied()
    }
}

/// A stop: kind, tick time (s), and the value that tripped against its limit (same units).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct StopEvent {
    /// Why.
    pub kind: StopKind,
    /// Time of the tick, s.
    pub time: f64,
    /// The offending value (N, N·m, ms, m or J), NaN when there is none.
    pub value: f64,
    /// The limit it passed, same unit, NaN when there is none.
    pub limit: f64,
}

impl StopEvent {
    /// A stop without a value.
    pub fn plain(kind: StopKind, time: f64) -> Self {
        StopEvent {
            kind,
            time,
            value: f64::NAN,
            limit: f64::NAN,
        }
    }

    /// One line for humans (formats, so call it outside the loop), naming the links
    /// generically ("sensor record", "robot feedback").
    pub fn reason(&self) -> Option<String> {
        self.reason_for("sensor", "robot")
    }

    /// One line for humans naming the links' protocols, e.g. `reason_for("RDT", "EGM")`:
    /// "no valid RDT record", "no valid EGM feedback" (formats, so call it outside the loop).
    pub fn reason_for(&self, sensor: &str, robot: &str) -> Option<String> {
        let (v, l, t) = (self.value, self.limit, self.time);
        Some(match self.kind {
            StopKind::Completed => return None,
            StopKind::User => format!("stopped by the user at {t:.3} s"),
            StopKind::ForceLimit => format!("force limit: |F| = {v:.1} N > {l:.1} N (force_limit) at {t:.3} s"),
            StopKind::MomentLimit => format!("moment limit: |M| = {v:.2} N·m > {l:.2} N·m (moment_limit) at {t:.3} s"),
            StopKind::SensorWatchdog => format!("sensor watchdog: no valid {sensor} record for {v:.1} ms > {l:.1} ms (watchdog_ms) at {t:.3} s"),
            StopKind::RobotWatchdog => format!("robot watchdog: no valid {robot} feedback for {v:.1} ms > {l:.1} ms (watchdog_ms) at {t:.3} s"),
            StopKind::Workspace => format!("workspace limit: commanded rod tip {:.1} mm from its start > {:.1} mm (workspace) at {t:.3} s", v * 1e3, l * 1e3),
            StopKind::NonFinite => format!("the command stopped being finite at {t:.3} s"),
            StopKind::Diverged => format!("diverged: energy {v:.4} J passed the divergence bound {l:.4} J at {t:.3} s"),
        })
    }
}

/// Checks the wrench limits (magnitudes of the measured force N and moment N·m).
pub fn check_wrench(
    limits: &SafetyLimits,
    force: &Vector3<f64>,
    moment: &Vector3<f64>,
    time: f64,
) -> Option<StopEvent> {
    let (f, m) = (force.norm(), moment.norm());
    if f.is_nan() || f > limits.force_limit {
        return Some(StopEvent {
            kind: StopKind::ForceLimit,
            time,
            value: f,
            limit: limits.force_limit,
        });
    }
    if m.is_nan() || m > limits.moment_limit {
        return Some(StopEvent {
            kind: StopKind::MomentLimit,
            time,
            value: m,
            limit: limits.moment_limit,
        });
    }
    None
}

/// Checks a commanded rod tip (m, `t`) against the workspace around `start` (m, `t`).
pub fn check_workspace(
    limits: &SafetyLimits,
    tip: &Vector3<f64>,
    start: &Vector3<f64>,
    time: f64,
) -> Option<StopEvent> {
    if !tip.iter().all(|v| v.is_finite()) {
        return Some(StopEvent::plain(StopKind::NonFinite, time));
    }
    let distance = (tip - start).norm();
    (distance > limits.workspace).then_some(StopEvent {
        kind: StopKind::Workspace,
        time,
        value: distance,
        limit: limits.workspace,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn limits_trip_above_and_on_nan() {
        let l = SafetyLimits::default();
        assert!(
            check_wrench(&l, &Vector3::new(300.0, 300.0, 0.0), &Vector3::zeros(), 0.0).is_none()
        );
        let e = check_wrench(&l, &Vector3::new(400.0, 400.0, 0.0), &Vector3::zeros(), 1.5).unwrap();
        assert_eq!(e.kind, StopKind::ForceLimit);
        assert!((e.value - 565.685).abs() < 1e-3);
        assert!(e.reason().unwrap().contains("565.7 N > 500.0 N"));
        assert_eq!(
            check_wrench(
                &l,
                &Vector3::new(f64::NAN, 0.0, 0.0),
                &Vector3::zeros(),
                0.0
            )
            .unwrap()
            .kind,
            StopKind::ForceLimit
        );
        assert_eq!(
            check_wrench(&l, &Vector3::zeros(), &Vector3::new(0.0, 101.0, 0.0), 0.0)
                .unwrap()
                .kind,
            StopKind::MomentLimit
        );
        let start = Vector3::new(0.005, 0.0, 0.0);
        assert!(check_workspace(&l, &Vector3::new(0.05, 0.0, 0.0), &start, 0.0).is_none());
        assert_eq!(
            check_workspace(&l, &Vector3::new(0.2, 0.0, 0.0), &start, 0.0)
                .unwrap()
                .kind,
            StopKind::Workspace
        );
        assert_eq!(
            check_workspace(&l, &Vector3::new(f64::INFINITY, 0.0, 0.0), &start, 0.0)
                .unwrap()
                .kind,
            StopKind::NonFinite
        );
    }

    #[test]
    fn codes_and_exit_codes() {
        for k in [
            StopKind::Completed,
            StopKind::User,
            StopKind::ForceLimit,
            StopKind::Diverged,
            StopKind::RobotWatchdog,
        ] {
            assert_eq!(StopKind::from_code(k.code()), Some(k));
        }
        assert_eq!(StopKind::from_code(0), None);
        assert_eq!(StopKind::Completed.exit_code(), 0);
        assert_eq!(StopKind::User.exit_code(), 130);
        assert_eq!(StopKind::SensorWatchdog.exit_code(), 3);
        assert_eq!(StopKind::ForceLimit.status(), "stopped");
    }

    #[test]
    fn invalid_limits_are_errors() {
        assert!(SafetyLimits {
            force_limit: 0.0,
            ..Default::default()
        }
        .validate()
        .is_err());
        assert!(SafetyLimits {
            watchdog_ms: f64::NAN,
            ..Default::default()
        }
        .validate()
        .is_err());
        assert!(SafetyLimits::default().validate().is_ok());
    }
}
