//! Kinematic quantities shared by the world, the facility and the compensators: the relative
//! motion of the servicer in the mockup frame `t` and a wrench on the target's collision frame.
//! A leaf module (it imports nothing of the crate), so that every other module may use it.

use nalgebra::{UnitQuaternion, Vector3};

/// Pose and twist of the servicer body frame relative to the target frame `t`, expressed in `t`:
/// what the robot is commanded to reproduce, and what it actually reproduces.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RelativeMotion {
    /// Position of the servicer's CoM in `t`, m.
    pub position: Vector3<f64>,
    /// Attitude of the servicer relative to `t` (servicer to `t`).
    pub orientation: UnitQuaternion<f64>,
    /// Rate of `position` (seen in `t`), m/s.
    pub velocity: Vector3<f64>,
    /// Angular velocity of the servicer relative to `t`, expressed in `t`, rad/s.
    pub angular_velocity: Vector3<f64>,
}

impl RelativeMotion {
    /// Position of a point fixed in the servicer (body coordinates) in `t`, eq. (3)/(25), m.
    pub fn point(&self, r_body: &Vector3<f64>) -> Vector3<f64> {
        self.position + self.orientation * r_body
    }

    /// Velocity of a point fixed in the servicer, seen in `t`, eq. (4)/(26), m/s.
    pub fn point_velocity(&self, r_body: &Vector3<f64>) -> Vector3<f64> {
        self.velocity + self.angular_velocity.cross(&(self.orientation * r_body))
    }

    /// [`RelativeMotion::point`] and [`RelativeMotion::point_velocity`] of one point (m, m/s),
    /// the point rotated once: the same arithmetic, bit for bit.
    pub fn point_and_velocity(&self, r_body: &Vector3<f64>) -> (Vector3<f64>, Vector3<f64>) {
        let r = self.orientation * r_body;
        (
            self.position + r,
            self.velocity + self.angular_velocity.cross(&r),
        )
    }
}

/// A wrench on the target's collision frame: force (N) and moment about the sensor origin
/// (N·m), both expressed in the target frame `t`.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct FrameWrench {
    /// Force on the frame, `t` frame, N.
    pub force: Vector3<f64>,
    /// Moment about the sensor origin, `t` frame, N·m.
    pub moment: Vector3<f64>,
}

impl FrameWrench {
    /// The wrench on the frame of a force `force_on_rod` (N, `t`) acting on the rod at `point`
    /// (m, `t`): the frame gets the opposite force, with its moment about `sensor_origin`.
    pub fn from_rod_force(
        force_on_rod: &Vector3<f64>,
        point: &Vector3<f64>,
        sensor_origin: &Vector3<f64>,
    ) -> Self {
        let force = -force_on_rod;
        FrameWrench {
            force,
            moment: (point - sensor_origin).cross(&force),
        }
    }
}
