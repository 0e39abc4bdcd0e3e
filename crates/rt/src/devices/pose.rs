//! The one place where the scenario's relative motion meets a robot's poses, for every robot
//! protocol (ABB EGM, KUKA RSI, ...).
//!
//! The robot reproduces the pose of the servicer relative to the target mockup frame `t`
//! ([`RelativeMotion`]: servicer body frame in `t`, metres, SI). A robot's external-motion
//! interface speaks poses of the tool frame in the frame the motion was activated in (a work
//! object or base, call it `e`), in millimetres and unit quaternions `[w, x, y, z]`
//! ([`PoseMm`]), and speeds in mm/s and deg/s ([`TargetMm`]); each protocol converts these to
//! its own wire form (EGM: the same; RSI: X, Y, Z and A, B, C angles). The mapping
//! ([`PoseMapping`], built once from the options' `offset_mm` and `rotation`) is
//!
//! ```text
//! p_e [mm]     = 1000 · (o + R · p_t [m])          o: origin of t in e (the base offset)
//! q_e          = R ⊗ q_t                           R: rotation from t to e
//! v_e [mm/s]   = 1000 · R · v_t [m/s]
//! ω_e [deg/s]  = (180/π) · R · ω_t [rad/s]
//! ```
//!
//! so the robot's tool frame is the servicer's body frame (origin at the servicer's centre of
//! mass of the virtual model, the rod tip at `rod.tip` in it): define the robot's tool data
//! that way. With the defaults (`o = 0`, `R = I`) a device pose is the relative pose itself, in
//! mm.
//!
//! The error keys of a bad mapping stay `egm_offset_mm` and `egm_rotation` for every protocol
//! (the tests and the CLI's messages name them so).

use nalgebra::{Quaternion, UnitQuaternion, Vector3};

use hilcontact_core::world::RelativeMotion;

use crate::error::{Result, RtError};

/// A device pose: tool position (mm) and orientation (`[w, x, y, z]`) in the robot's frame
/// `e`.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct PoseMm {
    /// Position, mm.
    pub position_mm: [f64; 3],
    /// Unit quaternion `[w, x, y, z]` (tool to `e`).
    pub orientation: [f64; 4],
}

/// A device target: pose plus speed reference `[vx, vy, vz]` mm/s and `[wx, wy, wz]` deg/s.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct TargetMm {
    /// The pose.
    pub pose: PoseMm,
    /// Speed reference: linear mm/s, then angular deg/s (frame `e`).
    pub speed: [f64; 6],
}

/// The mapping between `t` (metres) and the robot's frame `e` (millimetres).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PoseMapping {
    /// Origin of `t` in `e`, m.
    offset: Vector3<f64>,
    /// Rotation from `t` to `e`.
    rotation: UnitQuaternion<f64>,
}

impl Default for PoseMapping {
    /// The identity: a device pose is the relative pose in mm.
    fn default() -> Self {
        PoseMapping {
            offset: Vector3::zeros(),
            rotation: UnitQuaternion::identity(),
        }
    }
}

impl PoseMapping {
    /// A mapping with the origin of `t` at `offset_mm` (mm, in `e`) and `t` rotated into `e`
    /// by the quaternion `rotation` (`[w, x, y, z]`, normalised here).
    pub fn new(offset_mm: [f64; 3], rotation: [f64; 4]) -> Result<Self> {
        if !offset_mm.iter().all(|v| v.is_finite()) {
            return Err(RtError::option(
                "egm_offset_mm",
                format!("must be 3 finite numbers (mm), got {offset_mm:?}"),
            ));
        }
        let q = Quaternion::new(rotation[0], rotation[1], rotation[2], rotation[3]);
        if !rotation.iter().all(|v| v.is_finite()) || q.norm() < 1e-9 {
            return Err(RtError::option(
                "egm_rotation",
                format!("must be a non-zero quaternion [w, x, y, z], got {rotation:?}"),
            ));
        }
        Ok(PoseMapping {
            offset: Vector3::from(offset_mm) * 1e-3,
            rotation: UnitQuaternion::new_normalize(q),
        })
    }

    /// The device target of a relative motion (pose and speed reference).
    pub fn to_device(&self, m: &RelativeMotion) -> TargetMm {
        let p = (self.offset + self.rotation * m.position) * 1e3;
        let q = self.rotation * m.orientation;
        let v = self.rotation * m.velocity * 1e3;
        let w = (self.rotation * m.angular_velocity).map(f64::to_degrees);
        TargetMm {
            pose: PoseMm {
                position_mm: [p.x, p.y, p.z],
                orientation: [q.w, q.i, q.j, q.k],
            },
            speed: [v.x, v.y, v.z, w.x, w.y, w.z],
        }
    }

    /// Position (m) and orientation in `t` of a device pose (its quaternion is normalised).
    pub fn from_device(&self, pose: &PoseMm) -> (Vector3<f64>, UnitQuaternion<f64>) {
        let p_e = Vector3::from(pose.position_mm) * 1e-3;
        let [w, x, y, z] = pose.orientation;
        let q_e = UnitQuaternion::new_normalize(Quaternion::new(w, x, y, z));
        (
            self.rotation.inverse() * (p_e - self.offset),
            self.rotation.inverse() * q_e,
        )
    }

    /// Linear (m/s) and angular (rad/s) velocity in `t` of a device speed reference.
    pub fn speed_from_device(&self, speed: &[f64; 6]) -> (Vector3<f64>, Vector3<f64>) {
        let v = Vector3::new(speed[0], speed[1], speed[2]) * 1e-3;
        let w = Vector3::new(speed[3], speed[4], speed[5]).map(f64::to_radians);
        (self.rotation.inverse() * v, self.rotation.inverse() * w)
    }

    /// The relative motion of a device target (the inverse of [`PoseMapping::to_device`]).
    pub fn motion_from_device(&self, target: &TargetMm) -> RelativeMotion {
        let (position, orientation) = self.from_device(&target.pose);
        let (velocity, angular_velocity) = self.speed_from_device(&target.speed);
        RelativeMotion {
            position,
            orientation,
            velocity,
            angular_velocity,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn motion() -> RelativeMotion {
        RelativeMotion {
            position: Vector3::new(-0.995, 0.01, 0.002),
            orientation: UnitQuaternion::from_euler_angles(0.1, -0.2, 0.3),
            velocity: Vector3::new(0.02, 0.0, -0.001),
            angular_velocity: Vector3::new(0.0, 0.01, 0.05),
        }
    }

    #[test]
    fn identity_mapping_is_millimetres() {
        let t = PoseMapping::default().to_device(&motion());
        assert!((t.pose.position_mm[0] + 995.0).abs() < 1e-9);
        assert!((t.speed[0] - 20.0).abs() < 1e-12);
        assert!((t.speed[5] - 0.05f64.to_degrees()).abs() < 1e-12);
    }

    #[test]
    fn offset_and_rotation_round_trip() {
        let s = std::f64::consts::FRAC_1_SQRT_2;
        let map = PoseMapping::new([1500.0, -200.0, 800.0], [s, 0.0, 0.0, s]).unwrap(); // 90° about z
        let m = motion();
        let t = map.to_device(&m);
        // t's x axis is e's y axis: p_e = o + R p_t
        assert!(
            (t.pose.position_mm[0] - (1500.0 - 10.0)).abs() < 1e-9,
            "{:?}",
            t.pose
        );
        assert!((t.pose.position_mm[1] - (-200.0 - 995.0)).abs() < 1e-9);
        let back = map.motion_from_device(&t);
        assert!((back.position - m.position).norm() < 1e-12);
        assert!(back.orientation.angle_to(&m.orientation) < 1e-12);
        assert!((back.velocity - m.velocity).norm() < 1e-15);
        assert!((back.angular_velocity - m.angular_velocity).norm() < 1e-15);
    }

    #[test]
    fn bad_options_are_errors() {
        assert!(PoseMapping::new([f64::NAN, 0.0, 0.0], [1.0, 0.0, 0.0, 0.0]).is_err());
        assert!(PoseMapping::new([0.0; 3], [0.0; 4]).is_err());
    }
}
