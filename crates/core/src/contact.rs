//! The contact law between the rod tip and the walls: the one definition used by the
//! facility model, the ideal reference and the metrics.
//!
//! A wall is a point and a unit normal `n` pointing from the wall into free space.
//! Penetration `d = max(0, −(p_tip − p_wall)·n)`, penetration rate `ḋ = −v_tip·n`.
//! The force on the rod is `max(0, f(d, ḋ))·n` while `d > 0`: a contact never pulls.
//!
//! With friction ([`Friction`], `[contact.friction]`), each pushing wall adds a tangential
//! force against the tip's sliding velocity `v_t = v − (v·n)·n`, regularised Coulomb:
//! `F_t = −μ(|v_t|)·F_n·v_t / √(|v_t|² + v_ε²)`, with the Stribeck curve
//! `μ(s) = μ_k + (μ_s − μ_k)·exp(−(s/v_s)²)` (docs/model.md, "Friction").

use nalgebra::Vector3;

use crate::shapes::ShapePairs;
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

/// Which contact law: a scenario's `[contact] model` and a calibration's `[law] model`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, Default, JsonSchema)]
#[serde(rename_all = "kebab-case")]
pub enum ContactModelKind {
    /// Linear spring-damper, eq. (5).
    #[default]
    Linear,
    /// Hunt-Crossley: `F = k·d^n + c·d^n·ḋ`.
    HuntCrossley,
}

/// The contact law chosen by a scenario (static dispatch, no allocation).
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum ContactModel {
    /// Linear spring-damper, eq. (5).
    Linear(LinearSpringDamper),
    /// Hunt-Crossley.
    HuntCrossley(HuntCrossley),
}

impl ContactModel {
    /// The law of `kind` with stiffness k (N/m linear, N/mⁿ Hunt-Crossley), damping c (N·s/m
    /// linear, N·s/mⁿ⁺¹ Hunt-Crossley) and exponent n (Hunt-Crossley only).
    pub fn new(kind: ContactModelKind, stiffness: f64, damping: f64, exponent: f64) -> Self {
        match kind {
            ContactModelKind::Linear => {
                ContactModel::Linear(LinearSpringDamper { stiffness, damping })
            }
            ContactModelKind::HuntCrossley => ContactModel::HuntCrossley(HuntCrossley {
                stiffness,
                damping,
                exponent,
            }),
        }
    }
}

impl ContactLaw for ContactModel {
    fn normal_force(&self, d: f64, d_dot: f64) -> f64 {
        match self {
            ContactModel::Linear(law) => law.normal_force(d, d_dot),
            ContactModel::HuntCrossley(law) => law.normal_force(d, d_dot),
        }
    }
}

/// Regularised Coulomb friction with a static peak (Stribeck), stateless: the same force for
/// the same state wherever it is evaluated (the ideal reference's RK4 stages, the facility
/// model, the metrics).
///
/// ```text
/// μ(s) = μ_k + (μ_s − μ_k)·exp(−(s/v_s)²)                 s = |v_t|, the sliding speed
/// F_t  = −μ(s)·F_n·v_t / √(s² + v_ε²)                      tangential force on the rod
/// ```
/// Well above `v_ε` the force is Coulomb's `μ_k·F_n` against the sliding; below it, friction
/// acts as a viscous damper of coefficient `μ_s·F_n / v_ε` (N·s/m), which is how sticking is
/// modelled: a stuck contact creeps at a small fraction of `v_ε`. The friction force never
/// does positive work: its power `F_t·v_t ≤ 0`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Friction {
    /// Static coefficient μ_s (≥ μ_k): the peak of the Stribeck curve at zero sliding speed.
    pub static_coefficient: f64,
    /// Kinetic (sliding) coefficient μ_k.
    pub kinetic_coefficient: f64,
    /// Regularisation velocity v_ε, m/s (> 0): below it friction is viscous.
    pub stick_velocity: f64,
    /// Stribeck velocity v_s, m/s (> 0): the width of the static peak.
    pub stribeck_velocity: f64,
}

impl Friction {
    /// The friction coefficient μ(s) at sliding speed `s` (m/s), Stribeck curve.
    pub fn coefficient(&self, s: f64) -> f64 {
        let r = s / self.stribeck_velocity;
        self.kinetic_coefficient
            + (self.static_coefficient - self.kinetic_coefficient) * (-r * r).exp()
    }

    /// Tangential force on the rod, N, for a normal force `normal_force` (N, ≥ 0) and the
    /// sliding velocity `v_t` (m/s, tangential to the surface): `−μ(s)·F_n·v_t/√(s² + v_ε²)`.
    pub fn force(&self, normal_force: f64, v_t: &Vector3<f64>) -> Vector3<f64> {
        let s2 = v_t.norm_squared();
        if normal_force <= 0.0 || s2 == 0.0 {
            return Vector3::zeros();
        }
        let s = s2.sqrt();
        let eps = self.stick_velocity;
        v_t * (-self.coefficient(s) * normal_force / (s2 + eps * eps).sqrt())
    }
}

/// Friction between the contacting surfaces, `[contact.friction]` (both coefficients 0, the
/// default: frictionless).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct FrictionConfig {
    /// Kinetic (sliding) coefficient μ_k, 0 to 2 (steel on steel: about 0.1-0.3); 0 with
    /// `static` 0: frictionless.
    #[serde(default, rename = "kinetic")]
    #[schemars(range(min = 0.0, max = 2.0))]
    pub kinetic_coefficient: f64,
    /// Static coefficient μ_s, 0 to 2: the peak at zero sliding speed, ≥ `kinetic`; 0: the
    /// same as `kinetic`.
    #[serde(default, rename = "static")]
    #[schemars(range(min = 0.0, max = 2.0))]
    pub static_coefficient: f64,
    /// Regularisation velocity v_ε, m/s (1e-6 to 1): below it friction acts as viscous damping
    /// `μ_s·F_n/v_ε`, and a sticking contact creeps at a fraction of it.
    #[serde(default = "default_stick_velocity")]
    #[schemars(range(min = 1e-6, max = 1.0))]
    pub stick_velocity: f64,
    /// Stribeck velocity v_s, m/s (1e-6 to 1): the width of the static peak.
    #[serde(default = "default_stribeck_velocity")]
    #[schemars(range(min = 1e-6, max = 1.0))]
    pub stribeck_velocity: f64,
    /// Coefficients for pairs of shape materials (`[[contact.friction.pairs]]`): a contact
    /// between a servicer shape and a target shape whose `material`s are a listed pair (either
    /// order) takes that pair's coefficients; every other contact (the rod tip on the walls,
    /// shapes of unlisted materials) takes this table's. The velocities `stick_velocity` and
    /// `stribeck_velocity` are this table's for every pair.
    #[serde(default)]
    pub pairs: Vec<MaterialPairFriction>,
}

/// Friction between two shape materials, one `[[contact.friction.pairs]]` entry.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct MaterialPairFriction {
    /// The two materials, as the shapes' `material` names (either order; the same name twice
    /// for a material on itself).
    pub materials: [String; 2],
    /// Kinetic (sliding) coefficient μ_k of the pair, 0 to 2; 0 with `static` 0: frictionless.
    #[serde(default, rename = "kinetic")]
    #[schemars(range(min = 0.0, max = 2.0))]
    pub kinetic_coefficient: f64,
    /// Static coefficient μ_s of the pair, 0 to 2, ≥ `kinetic`; 0: the same as `kinetic`.
    #[serde(default, rename = "static")]
    #[schemars(range(min = 0.0, max = 2.0))]
    pub static_coefficient: f64,
}

fn default_stick_velocity() -> f64 {
    1e-3
}

fn default_stribeck_velocity() -> f64 {
    5e-3
}

impl Default for FrictionConfig {
    fn default() -> Self {
        FrictionConfig {
            kinetic_coefficient: 0.0,
            static_coefficient: 0.0,
            stick_velocity: default_stick_velocity(),
            stribeck_velocity: default_stribeck_velocity(),
            pairs: Vec::new(),
        }
    }
}

impl FrictionConfig {
    /// Whether both coefficients are 0 (no friction at all).
    pub fn is_frictionless(&self) -> bool {
        self.kinetic_coefficient == 0.0 && self.static_coefficient == 0.0
    }

    /// The friction law: `Ok(None)` when frictionless, `Err` with a message when the static
    /// coefficient is set below the kinetic one.
    pub fn friction(&self) -> std::result::Result<Option<Friction>, String> {
        self.law(self.kinetic_coefficient, self.static_coefficient)
    }

    /// The friction law of the `i`-th material pair (this table's velocities), as
    /// [`FrictionConfig::friction`].
    pub fn pair_friction(&self, i: usize) -> std::result::Result<Option<Friction>, String> {
        let p = &self.pairs[i];
        self.law(p.kinetic_coefficient, p.static_coefficient)
    }

    /// The law for coefficients `mu_k`, `mu_s` (μ_s 0: the same as μ_k) with this table's
    /// velocities: `None` when both are 0.
    fn law(&self, mu_k: f64, mu_s: f64) -> std::result::Result<Option<Friction>, String> {
        if mu_k == 0.0 && mu_s == 0.0 {
            return Ok(None);
        }
        let mu_s = if mu_s == 0.0 { mu_k } else { mu_s };
        if mu_s < mu_k {
            return Err(format!(
                "the static coefficient ({mu_s}) must not be below the kinetic one ({mu_k})"
            ));
        }
        Ok(Some(Friction {
            static_coefficient: mu_s,
            kinetic_coefficient: mu_k,
            stick_velocity: self.stick_velocity,
            stribeck_velocity: self.stribeck_velocity,
        }))
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

/// The contact force at one point of the rod (or summed over several), `t` frame.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct PointForce {
    /// The whole contact force on the rod (normal and friction parts), N.
    pub force: Vector3<f64>,
    /// Its friction (tangential) part, N (zero without friction).
    pub friction_force: Vector3<f64>,
    /// The friction's power, W (≤ 0: `Σ F_t·v_t`, the rate at which friction dissipates).
    pub friction_power: f64,
}

/// The collision geometry and the contact law: everything needed to compute the physical
/// contact force from the rod tip's motion relative to the target.
#[derive(Debug, Clone, PartialEq)]
pub struct ContactGeometry {
    /// The walls (target frame).
    pub walls: Vec<Wall>,
    /// The contact law.
    pub law: ContactModel,
    /// Friction between rod and walls, and between shapes of materials no pair names
    /// (`None`: frictionless).
    pub friction: Option<Friction>,
    /// Friction per pair of shapes, servicer shape `a` against target shape `b` at
    /// `a·(number of target shapes) + b`, from `[[contact.friction.pairs]]` (empty: every pair
    /// has `friction`).
    pub shape_friction: Vec<Option<Friction>>,
    /// The bodies' collision shapes (empty: only the rod tip against the walls).
    pub shapes: ShapePairs,
}

impl ContactGeometry {
    /// Physical contact force on the rod tip, target frame, N: the sum over the walls it
    /// penetrates of `max(0, f(d, ḋ))·n`, plus friction when there is any. Allocation-free.
    pub fn force_on_rod(&self, tip: &Vector3<f64>, tip_velocity: &Vector3<f64>) -> Vector3<f64> {
        self.force_with_added_damping(tip, tip_velocity, 0.0).force
    }

    /// The contact force on the rod tip (target frame) with its friction part and the friction
    /// power, with a damping `added_damping` (N·s/m) added to each pushing wall's normal force,
    /// `F_n = max(0, f(d, ḋ) + c_add·ḋ)` (never pulling; friction acts on that `F_n`): the
    /// facility's own losses (`facility.dissipation`), which the ideal reference does not have
    /// (0 there). Allocation-free.
    pub fn force_with_added_damping(
        &self,
        tip: &Vector3<f64>,
        tip_velocity: &Vector3<f64>,
        added_damping: f64,
    ) -> PointForce {
        let mut out = PointForce::default();
        for wall in &self.walls {
            let d = wall.penetration(tip);
            if d > 0.0 {
                let d_dot = wall.penetration_rate(tip_velocity);
                let mut f_n = self.law.normal_force(d, d_dot);
                if added_damping != 0.0 && f_n > 0.0 {
                    f_n = (f_n + added_damping * d_dot).max(0.0);
                }
                out.force += wall.normal * f_n;
                if let Some(friction) = &self.friction {
                    // sliding velocity: the tip's velocity along the wall
                    let v_t = tip_velocity - wall.normal * tip_velocity.dot(&wall.normal);
                    let f_t = friction.force(f_n, &v_t);
                    out.force += f_t;
                    out.friction_force += f_t;
                    out.friction_power += f_t.dot(&v_t);
                }
            }
        }
        out
    }

    /// The friction between servicer shape `servicer_shape` and target shape `target_shape`:
    /// their material pair's, or `friction` when no pair names them.
    pub fn friction_between(
        &self,
        servicer_shape: usize,
        target_shape: usize,
    ) -> Option<&Friction> {
        if self.shape_friction.is_empty() {
            return self.friction.as_ref();
        }
        self.shape_friction[servicer_shape * self.shapes.target.len() + target_shape].as_ref()
    }

    /// The force on the servicer at one contact point of penetration `d` (m) along the unit
    /// normal `normal` (from the target into free space), where the servicer's material point
    /// moves at `v` (m/s, relative to the target), with `added_damping` as in
    /// [`ContactGeometry::force_with_added_damping`]: the law along the normal and `friction`
    /// against the sliding velocity `v − (v·n)n`. Allocation-free.
    pub fn point_force(
        &self,
        d: f64,
        normal: &Vector3<f64>,
        v: &Vector3<f64>,
        added_damping: f64,
        friction: Option<&Friction>,
    ) -> PointForce {
        let d_dot = -v.dot(normal);
        let mut f_n = self.law.normal_force(d, d_dot);
        if added_damping != 0.0 && f_n > 0.0 {
            f_n = (f_n + added_damping * d_dot).max(0.0);
        }
        let mut out = PointForce {
            force: normal * f_n,
            ..PointForce::default()
        };
        if let Some(friction) = friction {
            let v_t = v - normal * v.dot(normal);
            let f_t = friction.force(f_n, &v_t);
            out.force += f_t;
            out.friction_force = f_t;
            out.friction_power = f_t.dot(&v_t);
        }
        out
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

    /// The same geometry mounted at `pose` (`t` frame): each wall's point `p ↦ R·p + t` and
    /// normal `n ↦ R·n`, the law and friction unchanged. The hardware as a facility has it
    /// when it is mounted off its nominal pose (`facility.mount_offset`,
    /// `facility.mount_rotation`).
    pub fn mounted(&self, pose: &nalgebra::Isometry3<f64>) -> ContactGeometry {
        ContactGeometry {
            walls: self
                .walls
                .iter()
                .map(|w| Wall {
                    point: pose.transform_point(&w.point.into()).coords,
                    normal: pose.rotation * w.normal,
                })
                .collect(),
            shapes: ShapePairs {
                servicer: self.shapes.servicer.clone(),
                target: self.shapes.target.iter().map(|t| t.moved(pose)).collect(),
            },
            ..self.clone()
        }
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
            friction: None,
            shape_friction: Vec::new(),
            shapes: ShapePairs::default(),
        };
        let f = geometry.force_on_rod(&Vector3::new(0.012, 0.0, 0.0), &Vector3::zeros());
        // the force on the rod pushes it back out, along −x
        assert!((f - Vector3::new(-2.0, 0.0, 0.0)).norm() < 1e-12);
    }
}
