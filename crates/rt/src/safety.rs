//! Safety limits of the real-time loop and the reasons a run stops.
//!
//! Every tick the loop checks, in this order: a user stop; the watchdogs (no valid sensor
//! record / robot feedback for `watchdog_ms`); the force and moment limits on the measured
//! wrench (magnitudes, sensor frame); then, on the new command, that it is finite and that
//! the commanded rod tip stays within `workspace` metres of where it started; and that the
//! virtual energy stays below the scenario's divergence bound. Any of them stops the run:
//! the robot is commanded to hold its last fed-back pose if that pose is inside the
//! workspace and within `hold_deviation` of the last command (else the last command, which
//! passed every check; [`hold_target`]), sensor streaming is stopped, the
//! sample log is drained, and the [`StopKind`] goes to `metrics.json` and the exit code.

use hilcontact_core::frames::RelativeMotion;
use nalgebra::Vector3;
use serde::{Deserialize, Serialize};

use crate::error::{Result, RtError};

/// The limits, with units. Defaults: 500 N, 100 N·m, 50 ms, 0.1 m, 20 mm.
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
    /// Largest distance between the robot's fed-back rod tip and the last command's for a
    /// stop to hold the robot where it reports to be, m (> 0); beyond it (or outside the
    /// workspace) the feedback is not trusted and the last command, which passed every
    /// check, is held instead.
    pub hold_deviation: f64,
    /// Speed at which a force or moment stop backs the robot away to its last contact-free
    /// pose, m/s (> 0).
    pub retreat_speed: f64,
    /// Longest retreat of a force or moment stop, m (> 0).
    pub retreat_distance: f64,
}

impl Default for SafetyLimits {
    fn default() -> Self {
        SafetyLimits {
            force_limit: 500.0,
            moment_limit: 100.0,
            watchdog_ms: 50.0,
            workspace: 0.1,
            hold_deviation: 0.02,
            retreat_speed: 0.02,
            retreat_distance: 0.02,
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
            ("hold_deviation", self.hold_deviation),
            ("retreat_speed", self.retreat_speed),
            ("retreat_distance", self.retreat_distance),
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

/// A stop of the real-time loop: the core's one vocabulary of how runs stop.
pub type StopEvent = hilcontact_core::metrics::Stop;
pub use hilcontact_core::metrics::StopKind;

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

/// The pose a stop holds the robot at (see the module doc): the fed-back pose `feedback` if
/// its rod tip (`rod`, servicer body frame, m) is inside the workspace around `start` (m, `t`)
/// and, once a command was sent, within `hold_deviation` of the last command's; else the last
/// command; `None` (send nothing) when neither is known and trusted.
pub fn hold_target(
    limits: &SafetyLimits,
    feedback: Option<RelativeMotion>,
    last_command: Option<RelativeMotion>,
    rod: &Vector3<f64>,
    start: &Vector3<f64>,
) -> Option<RelativeMotion> {
    let trusted = |pose: &RelativeMotion| {
        let tip = pose.point(rod);
        let inside = (tip - start).norm() <= limits.workspace;
        let tracking =
            last_command.is_none_or(|c| (c.point(rod) - tip).norm() <= limits.hold_deviation);
        inside && tracking
    };
    match (feedback, last_command) {
        (Some(f), _) if trusted(&f) => Some(f),
        (_, Some(c)) => Some(c),
        _ => None,
    }
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
    use hilcontact_core::metrics::Status;

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
        assert_eq!(StopKind::ForceLimit.status(), Status::Stopped);
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

    #[test]
    fn a_stop_holds_the_feedback_only_when_it_is_plausible() {
        use nalgebra::UnitQuaternion;
        let l = SafetyLimits::default();
        let rod = Vector3::new(1.0, 0.0, 0.0);
        let at = |x: f64| RelativeMotion {
            position: Vector3::new(x, 0.0, 0.0),
            orientation: UnitQuaternion::identity(),
            velocity: Vector3::zeros(),
            angular_velocity: Vector3::zeros(),
        };
        let start = at(-0.995).point(&rod);
        // tracking: the robot 5 mm behind the command is held where it is
        let held = hold_target(&l, Some(at(-0.990)), Some(at(-0.985)), &rod, &start).unwrap();
        assert_eq!(held.position.x, -0.990);
        // a feedback 300 mm off (inside a 100 m plausibility bound, outside the workspace):
        // the last command is held, not the bogus pose
        let held = hold_target(&l, Some(at(-0.695)), Some(at(-0.985)), &rod, &start).unwrap();
        assert_eq!(held.position.x, -0.985);
        // inside the workspace but 50 mm from the command: the command too
        let held = hold_target(&l, Some(at(-0.935)), Some(at(-0.985)), &rod, &start).unwrap();
        assert_eq!(held.position.x, -0.985);
        // before any command (a refused start): the robot's own pose if inside the workspace,
        // else nothing at all
        assert_eq!(
            hold_target(&l, Some(at(-0.945)), None, &rod, &start)
                .unwrap()
                .position
                .x,
            -0.945
        );
        assert!(hold_target(&l, Some(at(0.4)), None, &rod, &start).is_none());
        assert!(hold_target(&l, None, None, &rod, &start).is_none());
    }
}
