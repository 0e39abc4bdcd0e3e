//! The robot's actual motion at the loop's rate from feedback at the controller's rate.
//!
//! EGM feedback carries poses only (no velocity), every 4 ms, while the loop runs every 1 ms.
//! The estimator keeps the last three fed-back poses with the controller's time stamps,
//! differentiates them in the controller's time (velocity, and with [`Extrapolation::Quadratic`]
//! acceleration), and extrapolates from the local receive time of the newest feedback to the
//! tick's time. Extrapolation is capped at [`MAX_EXTRAPOLATION`]; beyond it the pose is held
//! (the watchdog stops the run long before a stale estimate matters).

use nalgebra::{UnitQuaternion, Vector3};
use serde::{Deserialize, Serialize};

use hilcontact_core::world::RelativeMotion;

use crate::safety::CycleMeter;

/// Longest extrapolation, s.
pub const MAX_EXTRAPOLATION: f64 = 0.012;

/// Fastest rod-tip motion a fed-back pose may show against the previous one, m/s: far above
/// what a robot reproducing a docking contact moves (mm/s to cm/s), far below a wrong frame
/// or a corrupted message. A pose beyond it is rejected ([`FeedbackEstimator::push`]).
pub const MAX_FEEDBACK_SPEED: f64 = 1.0;
/// Fastest rotation a fed-back pose may show, rad/s.
pub const MAX_FEEDBACK_ROTATION: f64 = 2.0;
/// The shortest time the speed limits are applied over, s (one EGM cycle), and the
/// measurement margins added to them, m and rad.
pub const FEEDBACK_MIN_INTERVAL: f64 = 0.004;
const FEEDBACK_MARGIN: (f64, f64) = (0.001, 0.01);

/// How the actual motion between feedback messages is estimated.
#[derive(
    Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, Default, schemars::JsonSchema,
)]
#[serde(rename_all = "kebab-case")]
pub enum Extrapolation {
    /// The last fed-back pose, with the velocity of the last two (no extrapolation).
    Hold,
    /// Constant velocity from the last two poses.
    Linear,
    /// Constant acceleration from the last three poses (default).
    #[default]
    Quadratic,
}

#[derive(Debug, Clone, Copy)]
struct Fed {
    robot_time: f64,
    local_ns: u64,
    position: Vector3<f64>,
    orientation: UnitQuaternion<f64>,
}

/// Estimates the actual relative motion (`t` frame) from timestamped feedback poses.
#[derive(Debug, Clone)]
pub struct FeedbackEstimator {
    mode: Extrapolation,
    fed: [Option<Fed>; 3],
    /// The robot's cycle measured from the accepted poses' controller times (unchecked until
    /// [`FeedbackEstimator::measure_cycle`]).
    pub cycle: CycleMeter,
}

impl FeedbackEstimator {
    /// An estimator with no feedback yet.
    pub fn new(mode: Extrapolation) -> Self {
        FeedbackEstimator {
            mode,
            fed: [None; 3],
            cycle: CycleMeter::new(0.0, 0.0),
        }
    }

    /// Measures the robot's cycle against `configured` s within `tolerance` (relative) from
    /// the controller times of the poses accepted from now on ([`CycleMeter`]).
    pub fn measure_cycle(&mut self, configured: f64, tolerance: f64) {
        self.cycle = CycleMeter::new(configured, tolerance);
    }

    /// Adds a fed-back pose: controller time (s), local receive time (ns), position (m, `t`),
    /// orientation (servicer to `t`).
    ///
    /// Returns false, and keeps nothing, for a pose that moved farther from the previous one
    /// than a robot can in the time between them (local time, at least
    /// [`FEEDBACK_MIN_INTERVAL`]): [`MAX_FEEDBACK_SPEED`], [`MAX_FEEDBACK_ROTATION`]. The
    /// caller counts it (`invalid`); a robot that really jumped is then silent to the loop,
    /// and the watchdog stops the run.
    pub fn push(
        &mut self,
        robot_time: f64,
        local_ns: u64,
        position: Vector3<f64>,
        orientation: UnitQuaternion<f64>,
    ) -> bool {
        if let Some(p) = self.fed[0] {
            let dt = (local_ns.saturating_sub(p.local_ns) as f64 * 1e-9).max(FEEDBACK_MIN_INTERVAL);
            let moved = (position - p.position).norm();
            let turned = p.orientation.angle_to(&orientation);
            if moved > MAX_FEEDBACK_SPEED * dt + FEEDBACK_MARGIN.0
                || turned > MAX_FEEDBACK_ROTATION * dt + FEEDBACK_MARGIN.1
            {
                return false;
            }
        }
        self.fed = [
            Some(Fed {
                robot_time,
                local_ns,
                position,
                orientation,
            }),
            self.fed[0],
            self.fed[1],
        ];
        self.cycle.push(robot_time);
        true
    }

    /// Whether any feedback arrived.
    pub fn has_feedback(&self) -> bool {
        self.fed[0].is_some()
    }

    /// The newest fed-back pose at rest (the hold target), if any.
    pub fn last_pose(&self) -> Option<RelativeMotion> {
        self.fed[0].map(|f| RelativeMotion {
            position: f.position,
            orientation: f.orientation,
            velocity: Vector3::zeros(),
            angular_velocity: Vector3::zeros(),
        })
    }

    /// The estimated actual motion at local time `now_ns`.
    pub fn estimate(&self, now_ns: u64) -> Option<RelativeMotion> {
        let f0 = self.fed[0]?;
        let rate = |a: &Fed, b: &Fed| -> Option<(Vector3<f64>, Vector3<f64>, f64)> {
            let mut dt = a.robot_time - b.robot_time;
            if dt.is_nan() || dt <= 1e-5 {
                dt = (a.local_ns.saturating_sub(b.local_ns)) as f64 * 1e-9;
            }
            (dt > 1e-5).then(|| {
                (
                    (a.position - b.position) / dt,
                    (a.orientation * b.orientation.inverse()).scaled_axis() / dt,
                    dt,
                )
            })
        };
        let (mut v, w, a) = match (
            self.fed[1].as_ref().and_then(|f1| rate(&f0, f1)),
            self.fed[2],
        ) {
            (None, _) => (Vector3::zeros(), Vector3::zeros(), Vector3::zeros()),
            (Some((v01, w, dt01)), f2) => {
                let f1 = self.fed[1].as_ref().map_or(f0, |f| *f);
                match (self.mode, f2.as_ref().and_then(|f2| rate(&f1, f2))) {
                    (Extrapolation::Quadratic, Some((v12, _, dt12))) => {
                        let a = (v01 - v12) / (0.5 * (dt01 + dt12));
                        (v01 + a * (0.5 * dt01), w, a)
                    }
                    _ => (v01, w, Vector3::zeros()),
                }
            }
        };
        let tau = match self.mode {
            Extrapolation::Hold => 0.0,
            _ => ((now_ns.saturating_sub(f0.local_ns)) as f64 * 1e-9).min(MAX_EXTRAPOLATION),
        };
        let position = f0.position + v * tau + a * (0.5 * tau * tau);
        v += a * tau;
        let orientation = UnitQuaternion::from_scaled_axis(w * tau) * f0.orientation;
        Some(RelativeMotion {
            position,
            orientation,
            velocity: v,
            angular_velocity: w,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn feed(e: &mut FeedbackEstimator, t: f64, p: Vector3<f64>) {
        e.push(t, (t * 1e9) as u64, p, UnitQuaternion::identity());
    }

    #[test]
    fn quadratic_is_exact_on_constant_acceleration() {
        let p = |t: f64| Vector3::new(0.01 + 0.02 * t - 0.25 * t * t, 0.0, 0.0);
        let mut e = FeedbackEstimator::new(Extrapolation::Quadratic);
        for k in 0..3 {
            feed(&mut e, 0.004 * k as f64, p(0.004 * k as f64));
        }
        let now = 0.008 + 0.003;
        let m = e.estimate((now * 1e9) as u64).unwrap();
        assert!(
            (m.position - p(now)).norm() < 1e-12,
            "{:?}",
            m.position - p(now)
        );
        assert!((m.velocity.x - (0.02 - 0.5 * now)).abs() < 1e-9);
    }

    #[test]
    fn linear_and_hold() {
        let mut e = FeedbackEstimator::new(Extrapolation::Linear);
        feed(&mut e, 0.0, Vector3::zeros());
        assert_eq!(e.estimate(1_000_000).unwrap().position, Vector3::zeros());
        feed(&mut e, 0.004, Vector3::new(0.0001, 0.0, 0.0));
        let m = e.estimate(6_000_000).unwrap();
        assert!((m.velocity.x - 0.025).abs() < 1e-12 && (m.position.x - 0.00015).abs() < 1e-12);
        // capped extrapolation
        let far = e.estimate(1_000_000_000).unwrap();
        assert!((far.position.x - (0.0001 + 0.025 * MAX_EXTRAPOLATION)).abs() < 1e-12);
        let mut h = FeedbackEstimator::new(Extrapolation::Hold);
        feed(&mut h, 0.0, Vector3::zeros());
        feed(&mut h, 0.004, Vector3::new(0.0001, 0.0, 0.0));
        let m = h.estimate(6_000_000).unwrap();
        assert_eq!(m.position.x, 0.0001);
        assert!((m.velocity.x - 0.025).abs() < 1e-12);
    }

    #[test]
    fn angular_velocity_in_t() {
        let mut e = FeedbackEstimator::new(Extrapolation::Linear);
        let w = Vector3::new(0.0, 0.0, 0.5);
        e.push(0.0, 0, Vector3::zeros(), UnitQuaternion::identity());
        e.push(
            0.004,
            4_000_000,
            Vector3::zeros(),
            UnitQuaternion::from_scaled_axis(w * 0.004),
        );
        let m = e.estimate(8_000_000).unwrap();
        assert!((m.angular_velocity - w).norm() < 1e-9);
        assert!(
            m.orientation
                .angle_to(&UnitQuaternion::from_scaled_axis(w * 0.008))
                < 1e-12
        );
    }

    #[test]
    fn a_jump_no_robot_makes_is_rejected_and_nothing_is_kept() {
        let q = UnitQuaternion::identity();
        let mut e = FeedbackEstimator::new(Extrapolation::Quadratic);
        assert!(e.push(0.0, 0, Vector3::new(0.005, 0.0, 0.0), q));
        // 0.1 mm in 4 ms (25 mm/s): a robot's motion
        assert!(e.push(0.004, 4_000_000, Vector3::new(0.0051, 0.0, 0.0), q));
        // 300 mm in the next 4 ms: rejected, the last pose kept
        assert!(!e.push(0.008, 8_000_000, Vector3::new(0.3051, 0.0, 0.0), q));
        assert_eq!(e.last_pose().unwrap().position.x, 0.0051);
        // a 90° turn in 4 ms: rejected too
        let turned = UnitQuaternion::from_euler_angles(0.0, 0.0, std::f64::consts::FRAC_PI_2);
        assert!(!e.push(0.008, 8_000_000, Vector3::new(0.0052, 0.0, 0.0), turned));
        assert!(e.push(0.008, 8_000_000, Vector3::new(0.0052, 0.0, 0.0), q));
    }
}
