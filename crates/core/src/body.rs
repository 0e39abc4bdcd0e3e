//! Free-floating rigid bodies: eqs. (1), (2) of the paper, with the gyroscopic term.
//!
//! ```text
//! v̇ = F / m                                  (1)   world frame, at the centre of mass
//! I ω̇ = τ_b − ω × (I ω)                      (2)   body frame (the paper writes Iω×ω)
//! q̇ = ½ q ⊗ (0, ω)                                attitude, body to world
//! ```
//! Two integrators: [`BodyState::step_kick_drift`] for the virtual dynamics of the HIL loop
//! (wrench held over a control period; a leapfrog splitting, second order and symplectic, so
//! a delay-free loop neither gains nor loses energy), and [`BodyRate`] arithmetic for the RK4 ideal reference.

use nalgebra::{Matrix3, Quaternion, UnitQuaternion, Vector3};

/// Mass properties of a rigid body.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MassProperties {
    /// Mass m, kg.
    pub mass: f64,
    /// Inertia tensor I about the centre of mass, body frame, kg·m².
    pub inertia: Matrix3<f64>,
    /// I⁻¹, 1/(kg·m²).
    pub inertia_inv: Matrix3<f64>,
}

impl MassProperties {
    /// Mass properties from a mass (kg) and an inertia tensor (kg·m², positive definite).
    pub fn new(mass: f64, inertia: Matrix3<f64>) -> Self {
        let inertia_inv = inertia.try_inverse().unwrap_or_else(Matrix3::zeros);
        MassProperties {
            mass,
            inertia,
            inertia_inv,
        }
    }

    /// Angular acceleration in the body frame, eq. (2): `I⁻¹ (τ_b − ω × Iω)`, rad/s².
    pub fn angular_acceleration(
        &self,
        angular_velocity: &Vector3<f64>,
        torque_body: &Vector3<f64>,
    ) -> Vector3<f64> {
        self.inertia_inv
            * (torque_body - angular_velocity.cross(&(self.inertia * angular_velocity)))
    }
}

/// Kinematic state of a free-floating rigid body.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct BodyState {
    /// Centre-of-mass position, world frame, m.
    pub position: Vector3<f64>,
    /// Attitude, body to world.
    pub orientation: UnitQuaternion<f64>,
    /// Centre-of-mass velocity, world frame, m/s.
    pub velocity: Vector3<f64>,
    /// Angular velocity, body frame, rad/s.
    pub angular_velocity: Vector3<f64>,
}

/// Time derivative of a [`BodyState`] (and, scaled by a step, an increment of it).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct BodyRate {
    /// ṗ = v, m/s.
    pub velocity: Vector3<f64>,
    /// q̇ = ½ q ⊗ (0, ω), 1/s.
    pub orientation_rate: Quaternion<f64>,
    /// v̇, m/s².
    pub acceleration: Vector3<f64>,
    /// ω̇ (body frame), rad/s².
    pub angular_acceleration: Vector3<f64>,
}

impl BodyRate {
    /// The RK4 average `(k1 + 2 k2 + 2 k3 + k4) / 6`.
    pub fn rk4_average(k1: &BodyRate, k2: &BodyRate, k3: &BodyRate, k4: &BodyRate) -> BodyRate {
        let avg3 = |a: Vector3<f64>, b: Vector3<f64>, c: Vector3<f64>, d: Vector3<f64>| {
            (a + 2.0 * b + 2.0 * c + d) / 6.0
        };
        BodyRate {
            velocity: avg3(k1.velocity, k2.velocity, k3.velocity, k4.velocity),
            orientation_rate: (k1.orientation_rate
                + k2.orientation_rate * 2.0
                + k3.orientation_rate * 2.0
                + k4.orientation_rate)
                / 6.0,
            acceleration: avg3(
                k1.acceleration,
                k2.acceleration,
                k3.acceleration,
                k4.acceleration,
            ),
            angular_acceleration: avg3(
                k1.angular_acceleration,
                k2.angular_acceleration,
                k3.angular_acceleration,
                k4.angular_acceleration,
            ),
        }
    }
}

impl BodyState {
    /// Angular velocity in the world frame, rad/s.
    pub fn angular_velocity_world(&self) -> Vector3<f64> {
        self.orientation * self.angular_velocity
    }

    /// Velocity (world frame) of a point fixed in the body, given in body coordinates.
    pub fn point_velocity(&self, point_body: &Vector3<f64>) -> Vector3<f64> {
        self.velocity
            + self
                .angular_velocity_world()
                .cross(&(self.orientation * point_body))
    }

    /// State derivative under a force (world, at the CoM, N) and a torque (world, about the CoM, N·m).
    pub fn rate(
        &self,
        mp: &MassProperties,
        force_world: &Vector3<f64>,
        torque_world: &Vector3<f64>,
    ) -> BodyRate {
        let torque_body = self.orientation.inverse_transform_vector(torque_world);
        BodyRate {
            velocity: self.velocity,
            orientation_rate: self.orientation.quaternion()
                * Quaternion::from_imag(self.angular_velocity)
                * 0.5,
            acceleration: force_world / mp.mass,
            angular_acceleration: mp.angular_acceleration(&self.angular_velocity, &torque_body),
        }
    }

    /// The state advanced by `rate · h` (explicit increment; the attitude is renormalised).
    pub fn advanced(&self, rate: &BodyRate, h: f64) -> BodyState {
        BodyState {
            position: self.position + rate.velocity * h,
            orientation: UnitQuaternion::new_normalize(
                self.orientation.quaternion() + rate.orientation_rate * h,
            ),
            velocity: self.velocity + rate.acceleration * h,
            angular_velocity: self.angular_velocity + rate.angular_acceleration * h,
        }
    }

    /// One step of the virtual dynamics with the wrench held constant over `h` (zero-order
    /// hold): a kick, then a drift (the splitting of the leapfrog / Störmer–Verlet method).
    ///
    /// ```text
    /// kick:   v ← v + h F/m,   L_world ← L_world + h τ_world   (at the attitude of the tick)
    /// drift:  force- and torque-free motion over h            ([`BodyState::drift`])
    /// ```
    /// The wrench is the one measured at the tick (a function of the pose at the tick), so
    /// the velocities the step leaves are those of the middle of the coming period, as in
    /// the leapfrog: second order in `h` for position-dependent wrenches, in translation and
    /// in rotation alike, and symplectic (a delay-free loop neither gains nor loses energy).
    /// Allocation-free.
    pub fn step_kick_drift(
        &mut self,
        mp: &MassProperties,
        force_world: &Vector3<f64>,
        torque_world: &Vector3<f64>,
        h: f64,
    ) {
        self.kick(mp, force_world, torque_world, h);
        self.drift(mp, h);
    }

    /// Force- and torque-free motion over `h`: translation exact, rotation (eq. 2 without
    /// torque) by one RK4 step; a body that does not turn only translates.
    pub fn drift(&mut self, mp: &MassProperties, h: f64) {
        if self.angular_velocity == Vector3::zeros() {
            self.position += self.velocity * h;
            return;
        }
        let k1 = self.free_rate(mp);
        let k2 = self.advanced(&k1, 0.5 * h).free_rate(mp);
        let k3 = self.advanced(&k2, 0.5 * h).free_rate(mp);
        let k4 = self.advanced(&k3, h).free_rate(mp);
        *self = self.advanced(&BodyRate::rk4_average(&k1, &k2, &k3, &k4), h);
    }

    /// [`BodyState::drift`] of two bodies over the same `h`, the same numbers to the bit, with
    /// their RK4 stages side by side: two independent chains of dependent operations (each
    /// stage waits for the last one's square root and divisions) that the processor overlaps.
    pub fn drift_pair(
        a: &mut BodyState,
        mass_a: &MassProperties,
        b: &mut BodyState,
        mass_b: &MassProperties,
        h: f64,
    ) {
        if a.angular_velocity == Vector3::zeros() || b.angular_velocity == Vector3::zeros() {
            a.drift(mass_a, h);
            b.drift(mass_b, h);
            return;
        }
        let (a1, b1) = (a.free_rate(mass_a), b.free_rate(mass_b));
        let (a2, b2) = (
            a.advanced(&a1, 0.5 * h).free_rate(mass_a),
            b.advanced(&b1, 0.5 * h).free_rate(mass_b),
        );
        let (a3, b3) = (
            a.advanced(&a2, 0.5 * h).free_rate(mass_a),
            b.advanced(&b2, 0.5 * h).free_rate(mass_b),
        );
        let (a4, b4) = (
            a.advanced(&a3, h).free_rate(mass_a),
            b.advanced(&b3, h).free_rate(mass_b),
        );
        *a = a.advanced(&BodyRate::rk4_average(&a1, &a2, &a3, &a4), h);
        *b = b.advanced(&BodyRate::rk4_average(&b1, &b2, &b3, &b4), h);
    }

    /// The kick of [`BodyState::step_kick_drift`] alone (its first half): `v ← v + h F/m`
    /// (m/s), `ω ← ω + I⁻¹ Rᵀ h τ` (rad/s, body frame) for a force (N) and a torque (N·m),
    /// both in the world frame.
    pub fn kick(
        &mut self,
        mp: &MassProperties,
        force_world: &Vector3<f64>,
        torque_world: &Vector3<f64>,
        h: f64,
    ) {
        self.velocity += force_world * (h / mp.mass);
        if *torque_world != Vector3::zeros() {
            // ΔL = h τ in the world; in the body frame at this attitude Δω = I⁻¹ Rᵀ h τ
            let torque_body = self.orientation.inverse_transform_vector(torque_world);
            self.angular_velocity += mp.inertia_inv * torque_body * h;
        }
    }

    /// [`BodyState::rate`] with no force and no torque, to the bit (a zero wrench turned
    /// into the body frame and divided by the mass is +0 exactly), without the rotation and
    /// the division that [`BodyState::drift`] would spend on it at each of its four stages.
    #[inline(always)]
    fn free_rate(&self, mp: &MassProperties) -> BodyRate {
        let zero = Vector3::zeros();
        BodyRate {
            velocity: self.velocity,
            orientation_rate: self.orientation.quaternion()
                * Quaternion::from_imag(self.angular_velocity)
                * 0.5,
            acceleration: zero,
            angular_acceleration: mp.angular_acceleration(&self.angular_velocity, &zero),
        }
    }

    /// Linear momentum, world frame, kg·m/s.
    pub fn linear_momentum(&self, mp: &MassProperties) -> Vector3<f64> {
        self.velocity * mp.mass
    }

    /// Angular momentum about the world origin, world frame, kg·m²/s.
    pub fn angular_momentum(&self, mp: &MassProperties) -> Vector3<f64> {
        self.position.cross(&(self.velocity * mp.mass))
            + self.orientation * (mp.inertia * self.angular_velocity)
    }

    /// Rotational kinetic energy ½ ωᵀ I ω, J.
    pub fn rotational_energy(&self, mp: &MassProperties) -> f64 {
        0.5 * self
            .angular_velocity
            .dot(&(mp.inertia * self.angular_velocity))
    }

    /// Total kinetic energy ½ m v² + ½ ωᵀ I ω, J.
    pub fn kinetic_energy(&self, mp: &MassProperties) -> f64 {
        0.5 * mp.mass * self.velocity.norm_squared() + self.rotational_energy(mp)
    }
}
