//! The contact law between the rod tip and the walls: the one definition used by the
//! facility model, the ideal reference and the metrics.
//!
//! A wall is a point and a unit normal `n` pointing from the wall into free space.
//! Penetration `d = max(0, −(p_tip − p_wall)·n)`, penetration rate `ḋ = −v_tip·n`.
//! The force on the rod is `max(0, f(d, ḋ))·n` while `d > 0`: a contact never pulls.

use nalgebra::Vector3;
use schemars::JsonSchema;
use serde::{Deserialize, Serialize};

/// A contact law: the normal force magnitude from penetration and penetration rate.
pub trait ContactLaw {
    /// Normal force magnitude, N, for penetration `d` (m, > 0) and rate `d_dot` (m/s).
    /// Implementations never return a negative value.
    fn normal_force(&self, d: f64, d_dot: f64) -> f64;
}

/// Linear spring-damper, eq. (5): `F = max(0, k·d + c·ḋ)`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LinearSpringDamper {
    /// Stiffness k, N/m.
    pub stiffness: f64,
    /// Damping c, N·s/m.
    pub damping: f64,
}

impl ContactLaw for LinearSpringDamper {
    fn normal_force(&self, d: f64, d_dot: f64) -> f64 {
        // eq. (5), clamped so that the contact never pulls
        (self.stiffness * d + self.damping * d_dot).max(0.0)
    }
}

/// Hunt-Crossley: `F = max(0, k·dⁿ + c·dⁿ·ḋ)` (damping vanishes with the penetration).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct HuntCrossley {
    /// Stiffness k, N/mⁿ.
    pub stiffness: f64,
    /// Damping c, N·s/mⁿ⁺¹.
    pub damping: f64,
    /// Exponent n (1.5 for Hertzian contact).
    pub exponent: f64,
}

impl ContactLaw for HuntCrossley {
    fn normal_force(&self, d: f64, d_dot: f64) -> f64 {
        let dn = d.powf(self.exponent);
        (dn * (self.stiffness + self.damping * d_dot)).max(0.0)
    }
}

/// The contact law chosen by a scenario (static dispatch, no allocation).
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum ContactModel {
    /// Linear spring-damper, eq. (5).
    Linear(LinearSpringDamper),
    /// Hunt-Crossley.
    HuntCrossley(HuntCrossley),
}

impl ContactLaw for ContactModel {
    fn normal_force(&self, d: f64, d_dot: f64) -> f64 {
        match self {
            ContactModel::Linear(law) => law.normal_force(d, d_dot),
            ContactModel::HuntCrossley(law) => law.normal_force(d, d_dot),
        }
    }
}

/// A planar wall of the collision frame, fixed in the target frame, as a scenario gives it
/// (`[[walls]]`, and the prior walls of `model-mediated`); the core checks it and normalises
/// its normal.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct WallConfig {
    /// Name for reports.
    #[serde(default)]
    pub name: String,
    /// A point of the wall, m (target frame).
    #[schemars(extend("x-value" = "vec3", "x-magnitude" = 1e3))]
    pub point: [f64; 3],
    /// Normal from the wall into free space (non-zero; normalised by the core).
    #[schemars(extend("x-value" = "vec3", "x-magnitude" = 1e6))]
    pub normal: [f64; 3],
}

/// A planar wall fixed in the target frame.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Wall {
    /// A point of the wall, target frame, m.
    pub point: Vector3<f64>,
    /// Unit normal from the wall into free space, target frame.
    pub normal: Vector3<f64>,
}

impl Wall {
    /// Penetration `d = max(0, −(p − p_wall)·n)`, m.
    pub fn penetration(&self, tip: &Vector3<f64>) -> f64 {
        (-(tip - self.point).dot(&self.normal)).max(0.0)
    }

    /// Penetration rate `ḋ = −v·n`, m/s.
    pub fn penetration_rate(&self, tip_velocity: &Vector3<f64>) -> f64 {
        -tip_velocity.dot(&self.normal)
    }

    /// Signed distance `(p − p_wall)·n` of a point to the wall's plane along its normal, m
    /// (negative inside the wall).
    pub fn signed_distance(&self, point: &Vector3<f64>) -> f64 {
        (point - self.point).dot(&self.normal)
    }
}

/// The collision geometry and the contact law: everything needed to compute the physical
/// contact force from the rod tip's motion relative to the target.
#[derive(Debug, Clone, PartialEq)]
pub struct ContactGeometry {
    /// The walls (target frame).
    pub walls: Vec<Wall>,
    /// The contact law.
    pub law: ContactModel,
}

impl ContactGeometry {
    /// Physical contact force on the rod tip, target frame, N: the sum over the walls it
    /// penetrates of `max(0, f(d, ḋ))·n`. Allocation-free.
    pub fn force_on_rod(&self, tip: &Vector3<f64>, tip_velocity: &Vector3<f64>) -> Vector3<f64> {
        let mut force = Vector3::zeros();
        for wall in &self.walls {
            let d = wall.penetration(tip);
            if d > 0.0 {
                force += wall.normal
                    * self
                        .law
                        .normal_force(d, wall.penetration_rate(tip_velocity));
            }
        }
        force
    }

    /// Which walls push on the rod (bit `i` for wall `i`, the first 64 walls): the contact's
    /// active set. The force is smooth in the state while this set stays the same, so the
    /// reference integrator locates its changes.
    pub fn active_set(&self, tip: &Vector3<f64>, tip_velocity: &Vector3<f64>) -> u64 {
        let mut set = 0u64;
        for (i, wall) in self.walls.iter().enumerate().take(64) {
            let d = wall.penetration(tip);
            if d > 0.0
                && self
                    .law
                    .normal_force(d, wall.penetration_rate(tip_velocity))
                    > 0.0
            {
                set |= 1 << i;
            }
        }
        set
    }

    /// Smallest signed distance of the tip to the walls' planes (negative inside a wall), m;
    /// `+∞` without walls.
    pub fn clearance(&self, tip: &Vector3<f64>) -> f64 {
        self.walls
            .iter()
            .map(|w| (tip - w.point).dot(&w.normal))
            .fold(f64::INFINITY, f64::min)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn linear_law_never_pulls_and_matches_eq5() {
        let law = LinearSpringDamper {
            stiffness: 1000.0,
            damping: 50.0,
        };
        assert_eq!(law.normal_force(0.002, 0.01), 1000.0 * 0.002 + 50.0 * 0.01);
        // separating fast at small penetration: k d + c ḋ < 0 → 0, not a pull
        assert_eq!(law.normal_force(0.0001, -1.0), 0.0);
    }

    #[test]
    fn hunt_crossley_follows_power_law() {
        let law = HuntCrossley {
            stiffness: 1e6,
            damping: 0.0,
            exponent: 1.5,
        };
        let f1 = law.normal_force(0.001, 0.0);
        let f2 = law.normal_force(0.004, 0.0);
        assert!((f2 / f1 - 8.0).abs() < 1e-12); // (4)^1.5 = 8
    }

    #[test]
    fn wall_sign_convention() {
        // front wall at x = 0.01 facing −x; the tip at x = 0.012 penetrates 2 mm
        let wall = Wall {
            point: Vector3::new(0.01, 0.0, 0.0),
            normal: Vector3::new(-1.0, 0.0, 0.0),
        };
        assert!((wall.penetration(&Vector3::new(0.012, 0.3, 0.0)) - 0.002).abs() < 1e-15);
        assert_eq!(wall.penetration(&Vector3::new(0.009, 0.0, 0.0)), 0.0);
        assert_eq!(wall.penetration_rate(&Vector3::new(0.02, 0.0, 0.0)), 0.02);
        let geometry = ContactGeometry {
            walls: vec![wall],
            law: ContactModel::Linear(LinearSpringDamper {
                stiffness: 1000.0,
                damping: 0.0,
            }),
        };
        let f = geometry.force_on_rod(&Vector3::new(0.012, 0.0, 0.0), &Vector3::zeros());
        // the force on the rod pushes it back out, along −x
        assert!((f - Vector3::new(-2.0, 0.0, 0.0)).norm() < 1e-12);
    }
}
