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
        if self.keeps_angular_velocity(&k1, h) {
            // every stage sees ω to the bit: its ω̇ is k1's (the same numbers, not recomputed)
            let k2 = self.advanced(&k1, 0.5 * h).free_rate_with(&k1);
            let k3 = self.advanced(&k2, 0.5 * h).free_rate_with(&k1);
            let k4 = self.advanced(&k3, h).free_rate_with(&k1);
            *self = self.advanced(&BodyRate::rk4_average(&k1, &k2, &k3, &k4), h);
            return;
        }
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
        if a.keeps_angular_velocity(&a1, h) && b.keeps_angular_velocity(&b1, h) {
            // every stage sees ω to the bit, so ω̇ (a function of ω alone) is k1's at each
            let (a2, b2) = (
                a.advanced(&a1, 0.5 * h).free_rate_with(&a1),
                b.advanced(&b1, 0.5 * h).free_rate_with(&b1),
            );
            let (a3, b3) = (
                a.advanced(&a2, 0.5 * h).free_rate_with(&a1),
                b.advanced(&b2, 0.5 * h).free_rate_with(&b1),
            );
            let (a4, b4) = (
                a.advanced(&a3, h).free_rate_with(&a1),
                b.advanced(&b3, h).free_rate_with(&b1),
            );
            *a = a.advanced(&BodyRate::rk4_average(&a1, &a2, &a3, &a4), h);
            *b = b.advanced(&BodyRate::rk4_average(&b1, &b2, &b3, &b4), h);
            return;
        }
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

    /// Whether the RK4 stages of [`BodyState::drift`] over `h` from this state all have its
    /// angular velocity to the bit, given its free rate `k1`: `ω + ω̇·h/2` and `ω + ω̇·h` (the
    /// stages' increments, computed as [`BodyState::advanced`] computes them) are `ω`, bit for
    /// bit (a body turning so slowly that its ω̇ is below half an ulp of ω, e.g. at the
    /// 3e-19 rad/s that rounding leaves in `paper-table1`). Then every stage's ω̇, a function
    /// of ω alone, is `k1`'s.
    #[inline(always)]
    fn keeps_angular_velocity(&self, k1: &BodyRate, h: f64) -> bool {
        let same = |v: Vector3<f64>| {
            v.iter()
                .zip(self.angular_velocity.iter())
                .all(|(x, y)| x.to_bits() == y.to_bits())
        };
        same(self.angular_velocity + k1.angular_acceleration * (0.5 * h))
            && same(self.angular_velocity + k1.angular_acceleration * h)
    }

    /// [`BodyState::free_rate`] at a state whose angular velocity is, to the bit, that of the
    /// state `k1` is the free rate of ([`BodyState::keeps_angular_velocity`]): its ω̇ is
    /// `k1`'s, not computed again.
    #[inline(always)]
    fn free_rate_with(&self, k1: &BodyRate) -> BodyRate {
        BodyRate {
            velocity: self.velocity,
            orientation_rate: self.orientation.quaternion()
                * Quaternion::from_imag(self.angular_velocity)
                * 0.5,
            acceleration: Vector3::zeros(),
            angular_acceleration: k1.angular_acceleration,
        }
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

#[cfg(test)]
mod tests {
    use super::*;

    /// The free-flight RK4 of [`BodyState::drift`] with every stage's ω̇ computed (no shortcut).
    fn drift_every_stage(x: &BodyState, mp: &MassProperties, h: f64) -> BodyState {
        if x.angular_velocity == Vector3::zeros() {
            let mut y = *x;
            y.position += y.velocity * h;
            return y;
        }
        let k1 = x.free_rate(mp);
        let k2 = x.advanced(&k1, 0.5 * h).free_rate(mp);
        let k3 = x.advanced(&k2, 0.5 * h).free_rate(mp);
        let k4 = x.advanced(&k3, h).free_rate(mp);
        x.advanced(&BodyRate::rk4_average(&k1, &k2, &k3, &k4), h)
    }

    fn bits(x: &BodyState) -> Vec<u64> {
        x.position
            .iter()
            .chain(x.orientation.coords.iter())
            .chain(x.velocity.iter())
            .chain(x.angular_velocity.iter())
            .map(|v| v.to_bits())
            .collect()
    }

    /// A small deterministic generator (xorshift64*), uniform in [0, 1).
    struct Random(u64);

    impl Random {
        fn next(&mut self) -> f64 {
            self.0 ^= self.0 >> 12;
            self.0 ^= self.0 << 25;
            self.0 ^= self.0 >> 27;
            (self.0.wrapping_mul(0x2545_f491_4f6c_dd1d) >> 11) as f64 / (1u64 << 53) as f64
        }
        fn vector(&mut self, scale: f64) -> Vector3<f64> {
            Vector3::new(
                (2.0 * self.next() - 1.0) * scale,
                (2.0 * self.next() - 1.0) * scale,
                (2.0 * self.next() - 1.0) * scale,
            )
        }
    }

    /// The shortcut of bodies that turn too slowly for their ω to change (ω̇ reused across the
    /// stages) gives the RK4 with every stage computed, to the bit, for `drift` and `drift_pair`
    /// alike, over random states whose ω spans 1e-25..10 rad/s (both branches taken).
    #[test]
    fn drift_with_a_steady_angular_velocity_is_the_full_rk4_to_the_bit() {
        let mut random = Random(0x9e37_79b9_7f4a_7c15);
        let (mut steady, mut turning) = (0, 0);
        for case in 0..4000 {
            let state = |random: &mut Random| {
                let exponent = -25.0 + 26.0 * random.next();
                let orientation = UnitQuaternion::from_scaled_axis(random.vector(3.0));
                BodyState {
                    position: random.vector(2.0),
                    orientation,
                    velocity: random.vector(0.1),
                    angular_velocity: random.vector(10f64.powf(exponent)),
                }
            };
            let mass = |random: &mut Random| {
                let d = random.vector(1.0).map(|v| 50.0 + 4000.0 * v.abs());
                let mut inertia = Matrix3::from_diagonal(&d);
                if case % 2 == 1 {
                    // a full (still positive definite) tensor
                    let off = random.vector(10.0);
                    inertia[(0, 1)] = off.x;
                    inertia[(1, 0)] = off.x;
                    inertia[(0, 2)] = off.y;
                    inertia[(2, 0)] = off.y;
                    inertia[(1, 2)] = off.z;
                    inertia[(2, 1)] = off.z;
                }
                MassProperties::new(300.0 + 4000.0 * random.next(), inertia)
            };
            let (a, b) = (state(&mut random), state(&mut random));
            let (ma, mb) = (mass(&mut random), mass(&mut random));
            let h = 1e-4 * 10f64.powf(2.0 * random.next());
            if a.keeps_angular_velocity(&a.free_rate(&ma), h) {
                steady += 1;
            } else {
                turning += 1;
            }
            let (want_a, want_b) = (drift_every_stage(&a, &ma, h), drift_every_stage(&b, &mb, h));
            let mut got = a;
            got.drift(&ma, h);
            assert_eq!(bits(&got), bits(&want_a), "drift, case {case}");
            let (mut pa, mut pb) = (a, b);
            BodyState::drift_pair(&mut pa, &ma, &mut pb, &mb, h);
            assert_eq!(bits(&pa), bits(&want_a), "drift_pair a, case {case}");
            assert_eq!(bits(&pb), bits(&want_b), "drift_pair b, case {case}");
        }
        assert!(
            steady > 500 && turning > 500,
            "{steady} steady, {turning} turning"
        );
    }
}
