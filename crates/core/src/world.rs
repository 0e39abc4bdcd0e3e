//! The virtual world: servicer and target free-floating, the rod tip fixed in the servicer,
//! the walls and the sensor fixed in the target.
//!
//! Frames: world (inertial); body frames at each centre of mass; the target body frame is
//! the mockup frame `t` on the ground, in which the robot reproduces the relative pose of the
//! servicer (`t_from_servicer`) and in which walls, sensor origin and contact points are given.
//! A wrench "on the frame" is what the sensor measures: the force the rod exerts on the
//! target's collision frame, with its moment about the sensor origin.

use nalgebra::{Isometry3, Matrix3, Translation3, Vector3};

use crate::body::{BodyRate, BodyState, MassProperties};
use crate::contact::{ContactGeometry, ContactLaw, ContactModel};
pub use crate::frames::{FrameWrench, RelativeMotion};

/// Mass properties, rod and sensor: the fixed description of the two-body system.
#[derive(Debug, Clone, PartialEq)]
pub struct TwoBodySystem {
    /// Servicer mass properties.
    pub servicer: MassProperties,
    /// Target mass properties.
    pub target: MassProperties,
    /// Rod tip in the servicer body frame, m.
    pub rod_tip: Vector3<f64>,
    /// Sensor origin in the target frame, m.
    pub sensor_origin: Vector3<f64>,
    /// Walls and contact law.
    pub contact: ContactGeometry,
}

/// The physical contact between the bodies at one instant (`t` frame): what the facility's
/// sensor would measure, and its parts for the metrics.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Contact {
    /// The whole contact force on the rod (servicer), N.
    pub force: Vector3<f64>,
    /// Its friction (tangential) part, N; `force − friction_force` is the normal part.
    pub friction_force: Vector3<f64>,
    /// The wrench on the frame (the force on the target, its moment about the sensor origin).
    pub wrench: FrameWrench,
    /// The friction's power, W (≤ 0).
    pub friction_power: f64,
    /// The rod tip, m (`t`).
    pub tip: Vector3<f64>,
    /// How many contact laws act in parallel along the contact's normal `n̂` (the direction of
    /// the summed normal force): a linear law `k` at each point makes the contact as stiff as
    /// `law_factor·k` along `n̂`, the stiffness an identification along one normal finds.
    /// Exactly 1 for one pushing point, 0 without contact; for the rod tip against several
    /// walls `Σᵢ (nᵢ·n̂)²` (`nᵢ` a wall's normal: 2 for two walls side by side, `2cos²θ` for a
    /// groove of half-angle θ); NaN where shapes' points are among several (their depths are
    /// not each a plane's: [`TwoBodySystem::law_factor_at`] measures it).
    pub law_factor: f64,
}

/// The start of a step of the ideal reference ([`TwoBodySystem::step_reference_at`]): the
/// relative motion there and what the step reads of it, each computed once, by the step that
/// ended there or by [`TwoBodySystem::reference_start`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ReferenceStart {
    /// The relative motion of the servicer (`t`).
    pub rel: RelativeMotion,
    /// Its rod tip, `t`, m ([`RelativeMotion::point_and_velocity`]).
    pub tip: Vector3<f64>,
    /// The rod tip's velocity, `t`, m/s.
    pub tip_velocity: Vector3<f64>,
    /// The rod tip's clearance from the walls ([`ContactGeometry::clearance`], m), when the
    /// step that ended here computed it.
    clearance: Option<f64>,
    /// The contact here and its active set ([`TwoBodySystem::contact_and_active_set`]), when
    /// the step that ended here computed them (its last active set, fused with the contact
    /// that the next step's first RK4 stage and the reference's record read).
    known: Option<(Contact, u64)>,
}

/// The state of both bodies (world frame).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TwoBodyState {
    /// The servicer.
    pub servicer: BodyState,
    /// The target.
    pub target: BodyState,
}

impl TwoBodySystem {
    /// Reduced mass μ = m_s m_t / (m_s + m_t), kg.
    pub fn reduced_mass(&self) -> f64 {
        self.servicer.mass * self.target.mass / (self.servicer.mass + self.target.mass)
    }

    /// Pose and twist of the servicer relative to the target, in `t`.
    pub fn relative_motion(&self, x: &TwoBodyState) -> RelativeMotion {
        let (s, t) = (&x.servicer, &x.target);
        let r = s.position - t.position;
        // R_t (target to world) once, as a matrix: cheaper than four quaternion rotations
        let r_t = t.orientation.to_rotation_matrix();
        let w_t = r_t * t.angular_velocity;
        let orientation = t.orientation.inverse() * s.orientation;
        RelativeMotion {
            position: r_t.inverse_transform_vector(&r),
            orientation,
            // d/dt of Rᵀ r = Rᵀ (ṙ − ω_t × r)
            velocity: r_t.inverse_transform_vector(&(s.velocity - t.velocity - w_t.cross(&r))),
            // Rᵀ (ω_s,world − ω_t,world) = R_rel ω_s,body − ω_t,body
            angular_velocity: orientation * s.angular_velocity - t.angular_velocity,
        }
    }

    /// Kinetic energy of the relative motion (the barycentric kinetic energy), J:
    /// `½ μ |v_s − v_t|² + ½ ω_sᵀ I_s ω_s + ½ ω_tᵀ I_t ω_t`. Constant in free flight.
    pub fn energy(&self, x: &TwoBodyState) -> f64 {
        0.5 * self.reduced_mass() * (x.servicer.velocity - x.target.velocity).norm_squared()
            + x.servicer.rotational_energy(&self.servicer)
            + x.target.rotational_energy(&self.target)
    }

    /// Elastic energy stored in a linear or Hunt-Crossley contact, J (`∫ k dⁿ dd` per wall and
    /// per contact point of the shapes).
    pub fn contact_potential_energy(&self, x: &TwoBodyState) -> f64 {
        let tip = self.relative_motion(x).point(&self.rod_tip);
        let (k, n) = match self.contact.law {
            crate::contact::ContactModel::Linear(l) => (l.stiffness, 1.0),
            crate::contact::ContactModel::HuntCrossley(h) => (h.stiffness, h.exponent),
        };
        let walls: f64 = self
            .contact
            .walls
            .iter()
            .map(|w| k * w.penetration(&tip).powf(n + 1.0) / (n + 1.0))
            .sum();
        let mut shapes = 0.0;
        self.for_each_shape_contact(&self.relative_motion(x), |p| {
            shapes += k * p.depth.powf(n + 1.0) / (n + 1.0);
        });
        walls + shapes
    }

    /// Total linear momentum (world), kg·m/s.
    pub fn linear_momentum(&self, x: &TwoBodyState) -> Vector3<f64> {
        x.servicer.linear_momentum(&self.servicer) + x.target.linear_momentum(&self.target)
    }

    /// Total angular momentum about the world origin (world), kg·m²/s.
    pub fn angular_momentum(&self, x: &TwoBodyState) -> Vector3<f64> {
        x.servicer.angular_momentum(&self.servicer) + x.target.angular_momentum(&self.target)
    }

    /// World-frame wrenches on both bodies (force, torque about own CoM) for a wrench on the
    /// frame: the target gets it at the sensor origin (eqs. 1, 2 with `r × F`), the servicer
    /// the equal and opposite one, so momentum and angular momentum are conserved.
    pub fn body_wrenches(
        &self,
        x: &TwoBodyState,
        w: &FrameWrench,
    ) -> ([Vector3<f64>; 2], [Vector3<f64>; 2]) {
        let (s, t) = (&x.servicer, &x.target);
        let force = t.orientation * w.force;
        let moment = t.orientation * w.moment;
        let sensor_world = t.position + t.orientation * self.sensor_origin;
        let lever_t = (sensor_world - t.position).cross(&force);
        let lever_s = (sensor_world - s.position).cross(&force);
        let target_torque = moment + lever_t;
        let servicer_torque = -moment - lever_s;
        (
            [-force, force],
            [
                through_centre(servicer_torque, &force, &moment, &lever_s),
                through_centre(target_torque, &force, &moment, &lever_t),
            ],
        )
    }

    /// Changes the servicer's velocity relative to the target by `dv` (`t` frame, m/s), split
    /// between the bodies so that the linear momentum is unchanged. (Both centres of mass
    /// change velocity; the rotations do not. Not what the compensators' velocity correction
    /// uses: see [`TwoBodySystem::correct_tip_velocity`].)
    pub fn correct_relative_velocity(&self, x: &mut TwoBodyState, dv: &Vector3<f64>) {
        let dv_world = x.target.orientation * dv;
        let mu = self.reduced_mass();
        x.servicer.velocity += dv_world * (mu / self.servicer.mass);
        x.target.velocity -= dv_world * (mu / self.target.mass);
    }

    /// The rod tip's lever arms from the servicer's and the target's centres of mass (world), m.
    fn tip_arms(&self, x: &TwoBodyState) -> (Vector3<f64>, Vector3<f64>) {
        let arm_s = x.servicer.orientation * self.rod_tip;
        let tip = x.servicer.position + arm_s;
        (arm_s, tip - x.target.position)
    }

    /// The mobility of the rod tip, `K` (`t` frame, 1/kg): an impulse `J` on the servicer at
    /// its rod tip, with `−J` on the target at the same point, changes the tip's velocity
    /// relative to the target (as [`RelativeMotion::point_velocity`] gives it) by `K·J`:
    /// ```text
    /// K = (1/m_s + 1/m_t)·1 − [r_s]× I_s⁻¹ [r_s]× − [r_t]× I_t⁻¹ [r_t]×
    /// ```
    /// with `r_s`, `r_t` the tip from each centre of mass and the inverse inertias in the same
    /// frame. Symmetric positive definite; `1/K` along a direction is the effective mass the tip
    /// has there (the reduced mass when the tip lies on the line of the two centres of mass and
    /// the bodies do not turn). Exact for the energy: the impulse changes the kinetic energy by
    /// `J·(u + K·J/2)`, `u` the tip's relative velocity before it.
    pub fn tip_mobility(&self, x: &TwoBodyState) -> Matrix3<f64> {
        let (arm_s, arm_t) = self.tip_arms(x);
        let r_s = x.servicer.orientation.to_rotation_matrix();
        let r_t = x.target.orientation.to_rotation_matrix();
        let inv_s = r_s.matrix() * self.servicer.inertia_inv * r_s.matrix().transpose();
        let inv_t = r_t.matrix() * self.target.inertia_inv * r_t.matrix().transpose();
        let (cs, ct) = (arm_s.cross_matrix(), arm_t.cross_matrix());
        let world = Matrix3::identity() * (1.0 / self.servicer.mass + 1.0 / self.target.mass)
            - cs * inv_s * cs
            - ct * inv_t * ct;
        r_t.matrix().transpose() * world * r_t.matrix()
    }

    /// Applies the impulse `impulse` (`t` frame, N·s) to the servicer at its rod tip and the
    /// opposite one to the target at the same point: linear and angular momentum are unchanged,
    /// the tip's relative velocity changes by `K·impulse` ([`TwoBodySystem::tip_mobility`]).
    pub fn apply_tip_impulse(&self, x: &mut TwoBodyState, impulse: &Vector3<f64>) {
        let (arm_s, arm_t) = self.tip_arms(x);
        let j = x.target.orientation * impulse;
        x.servicer.velocity += j / self.servicer.mass;
        x.target.velocity -= j / self.target.mass;
        // ΔL = r × J in the world; Δω = I⁻¹ Rᵀ ΔL in the body frame
        let dl_s = x
            .servicer
            .orientation
            .inverse_transform_vector(&arm_s.cross(&j));
        let dl_t = x
            .target
            .orientation
            .inverse_transform_vector(&arm_t.cross(&-j));
        x.servicer.angular_velocity += self.servicer.inertia_inv * dl_s;
        x.target.angular_velocity += self.target.inertia_inv * dl_t;
    }

    /// Changes the rod tip's velocity relative to the target by `dv` (`t` frame, m/s) with the
    /// impulse at the tip that does it, `J = K⁻¹·dv` ([`TwoBodySystem::apply_tip_impulse`]): the
    /// velocity correction of the admittance-type compensators. Allocation-free.
    pub fn correct_tip_velocity(&self, x: &mut TwoBodyState, dv: &Vector3<f64>) {
        if *dv == Vector3::zeros() {
            return;
        }
        let k = self.tip_mobility(x);
        let impulse = match k.cholesky() {
            Some(c) => c.solve(dv),
            None => dv * self.reduced_mass(),
        };
        self.apply_tip_impulse(x, &impulse);
    }

    /// One control period of the virtual dynamics with the wrench held (zero-order hold), by
    /// [`crate::body::BodyState::step_kick_drift`] for each body.
    pub fn step_virtual(&self, x: &mut TwoBodyState, w: &FrameWrench, period: f64) {
        let ([f_s, f_t], [tau_s, tau_t]) = self.body_wrenches(x, w);
        // each body's kick then drift, the two drifts side by side (the same numbers)
        x.servicer.kick(&self.servicer, &f_s, &tau_s, period);
        x.target.kick(&self.target, &f_t, &tau_t, period);
        BodyState::drift_pair(
            &mut x.servicer,
            &self.servicer,
            &mut x.target,
            &self.target,
            period,
        );
    }

    /// The physical contact at a state of the true system.
    pub fn contact(&self, x: &TwoBodyState) -> Contact {
        self.contact_at(&self.relative_motion(x), 0.0)
    }

    /// The physical contact for a relative motion of the servicer: the force on the rod, its
    /// friction part, the wrench on the frame and the friction's power, with a damping
    /// `added_damping` (N·s/m) added to every pushing contact's normal force (the facility's
    /// own losses, `facility.dissipation`; 0 for the true system): the rod tip against the
    /// walls, then every contact point of the shapes ([`crate::shapes`]). Allocation-free.
    pub fn contact_at(&self, rel: &RelativeMotion, added_damping: f64) -> Contact {
        let (tip, tip_velocity) = rel.point_and_velocity(&self.rod_tip);
        self.contact_at_tip(rel, &tip, &tip_velocity, added_damping)
    }

    /// [`TwoBodySystem::contact_at`] with the rod tip of `rel` and its velocity given (`t`, m
    /// and m/s, as [`RelativeMotion::point_and_velocity`] gives them): the same contact, to the
    /// bit. Allocation-free.
    pub fn contact_at_tip(
        &self,
        rel: &RelativeMotion,
        tip: &Vector3<f64>,
        tip_velocity: &Vector3<f64>,
        added_damping: f64,
    ) -> Contact {
        self.contact_at_tip_noting(rel, tip, tip_velocity, added_damping, true, |_, _| {})
    }

    /// The contact at a reference step's start (the reference's record): as the step that ended
    /// there computed it, or with its active set ([`TwoBodySystem::contact_and_active_set`],
    /// kept in `start` for the step from there) where there are shapes (without shapes the
    /// step asks only the rod tip's active set, and the contact alone is computed).
    pub fn reference_contact(&self, start: &mut ReferenceStart) -> Contact {
        match start.known {
            Some((c, _)) => c,
            None if self.contact.shapes.is_empty() => {
                self.contact_at_tip(&start.rel, &start.tip, &start.tip_velocity, 0.0)
            }
            None => self.contact_and_active_set(start).0,
        }
    }

    /// The contact at a reference step's start and its active set
    /// ([`TwoBodySystem::contact_at_tip`] with no added damping and
    /// [`TwoBodySystem::active_set_at`]: the same numbers, to the bit), from one pass over the
    /// shapes' contact points, or as the step that ended there computed them; kept in `start`
    /// for the step from there.
    pub fn contact_and_active_set(&self, start: &mut ReferenceStart) -> (Contact, u64) {
        if let Some(known) = start.known {
            return known;
        }
        let known = self.contact_and_active_set_of(start, true);
        start.known = Some(known);
        known
    }

    /// [`TwoBodySystem::contact_and_active_set`] computed, the shapes' contact points looked
    /// for only if `shapes` (not where a free-flight step has just shown there are none).
    fn contact_and_active_set_of(&self, start: &ReferenceStart, shapes: bool) -> (Contact, u64) {
        let (rel, tip, tip_velocity) = (&start.rel, &start.tip, &start.tip_velocity);
        let mut set = self.contact.active_set(tip, tip_velocity);
        let c = self.contact_at_tip_noting(rel, tip, tip_velocity, 0.0, shapes, |point, v| {
            if self.pushes(point, v) {
                set = set.wrapping_add(point.id);
            }
        });
        (c, set)
    }

    /// [`TwoBodySystem::contact_at_tip`], calling `note` with every contact point of the shapes
    /// and its sliding velocity (`t`, m/s); the shapes looked at only if `shapes`.
    fn contact_at_tip_noting(
        &self,
        rel: &RelativeMotion,
        tip: &Vector3<f64>,
        tip_velocity: &Vector3<f64>,
        added_damping: f64,
        shapes: bool,
        mut note: impl FnMut(&crate::shapes::ContactPoint, &Vector3<f64>),
    ) -> Contact {
        let tip = *tip;
        let p = self
            .contact
            .force_with_added_damping(&tip, tip_velocity, added_damping);
        let mut c = Contact {
            force: p.force,
            friction_force: p.friction_force,
            wrench: FrameWrench::from_rod_force(&p.force, &tip, &self.sensor_origin),
            friction_power: p.friction_power,
            tip,
            law_factor: 0.0,
        };
        // the pushing points: their count, the walls' `S = Σᵢ nᵢnᵢᵀ` (for `law_factor`), and
        // whether shapes' points are among them
        let (mut pushing, mut spread, mut shaped) = (0usize, Matrix3::zeros(), false);
        if p.force != p.friction_force {
            for wall in &self.contact.walls {
                let d = wall.penetration(&tip);
                if d > 0.0 {
                    let d_dot = wall.penetration_rate(tip_velocity);
                    let f_n = self.contact.law.normal_force(d, d_dot);
                    if f_n > 0.0 && f_n + added_damping * d_dot > 0.0 {
                        pushing += 1;
                        spread += wall.normal * wall.normal.transpose();
                    }
                }
            }
        }
        if shapes {
            self.for_each_shape_contact_force(rel, added_damping, |point, f| {
                note(
                    point,
                    &(rel.velocity + rel.angular_velocity.cross(&(point.point - rel.position))),
                );
                let w = FrameWrench::from_rod_force(&f.force, &point.point, &self.sensor_origin);
                c.force += f.force;
                c.friction_force += f.friction_force;
                c.friction_power += f.friction_power;
                c.wrench.force += w.force;
                c.wrench.moment += w.moment;
                if f.force != f.friction_force {
                    pushing += 1;
                    shaped = true;
                }
            });
        }
        // `law_factor = n̂ᵀ S n̂`, `n̂` along the summed normal force
        c.law_factor = match (pushing, shaped) {
            (0, _) => 0.0,
            (1, _) => 1.0,
            (_, true) => f64::NAN,
            (_, false) => (c.force - c.friction_force)
                .try_normalize(0.0)
                .map_or(0.0, |n| n.dot(&(spread * n))),
        };
        c
    }

    /// [`Contact::law_factor`] of `contact` (the contact at `rel`, [`TwoBodySystem::contact_at`])
    /// where several points of shapes push: the stiffness along the summed normal `n̂` by a
    /// central difference of the normal force `N(s)` (the servicer at rest, translated by
    /// `s·n̂`), over the law's `k`: `λ = (N(−h) − N(h)) / (2h·k)`, `h` = 1e-8 m (exact for a
    /// linear law while no point enters or leaves within `h`); NaN for a Hunt-Crossley law, whose
    /// stiffness depends on the depth. `contact.law_factor` itself elsewhere. Allocation-free
    /// (two more contact evaluations).
    pub fn law_factor_at(&self, rel: &RelativeMotion, contact: &Contact) -> f64 {
        const H: f64 = 1e-8;
        if !contact.law_factor.is_nan() {
            return contact.law_factor;
        }
        let ContactModel::Linear(law) = self.contact.law else {
            return f64::NAN;
        };
        let Some(n) = (contact.force - contact.friction_force).try_normalize(0.0) else {
            return 0.0;
        };
        let normal_force = |s: f64| {
            let r = RelativeMotion {
                position: rel.position + n * s,
                velocity: Vector3::zeros(),
                angular_velocity: Vector3::zeros(),
                ..*rel
            };
            let c = self.contact_at(&r, 0.0);
            (c.force - c.friction_force).dot(&n)
        };
        (normal_force(-H) - normal_force(H)) / (2.0 * H * law.stiffness)
    }

    /// Calls `f` with every contact point of the shapes for a relative motion of the servicer
    /// (`t` frame) and the force on the servicer there (N, with its friction part), with
    /// `added_damping` as in [`TwoBodySystem::contact_at`] (whose shapes' part is the sum of
    /// these forces; the rod tip against the walls is not among them). Allocation-free.
    pub fn for_each_shape_contact_force(
        &self,
        rel: &RelativeMotion,
        added_damping: f64,
        mut f: impl FnMut(&crate::shapes::ContactPoint, &crate::contact::PointForce),
    ) {
        if self.contact.shapes.is_empty() {
            return;
        }
        self.contact
            .shapes
            .for_each_point(&servicer_pose(rel), |point| {
                let v = rel.velocity + rel.angular_velocity.cross(&(point.point - rel.position));
                let friction = self
                    .contact
                    .friction_between(point.servicer_shape, point.target_shape);
                let force = self.contact.point_force(
                    point.depth,
                    &point.normal,
                    &v,
                    added_damping,
                    friction,
                );
                f(point, &force);
            });
    }

    /// Calls `f` with every contact point of the shapes for a relative motion of the servicer
    /// (`t` frame; the rod tip against the walls is not among them). Allocation-free.
    pub fn for_each_shape_contact(
        &self,
        rel: &RelativeMotion,
        f: impl FnMut(&crate::shapes::ContactPoint),
    ) {
        if !self.contact.shapes.is_empty() {
            self.contact.shapes.for_each_point(&servicer_pose(rel), f);
        }
    }

    /// Rates of both bodies of the true system (the contact law closes the loop).
    pub fn true_rates(&self, x: &TwoBodyState) -> (BodyRate, BodyRate) {
        self.true_rates_and_friction_power(x).0
    }

    /// [`TwoBodySystem::true_rates`] and the power of the contact's friction, W (≤ 0).
    fn true_rates_and_friction_power(&self, x: &TwoBodyState) -> ((BodyRate, BodyRate), f64) {
        self.true_rates_at(x, &self.relative_motion(x))
    }

    /// [`TwoBodySystem::true_rates_and_friction_power`] with the relative motion at `x` given
    /// (`rel`, as [`TwoBodySystem::relative_motion`] gives it): the same numbers, to the bit.
    fn true_rates_at(&self, x: &TwoBodyState, rel: &RelativeMotion) -> ((BodyRate, BodyRate), f64) {
        self.true_rates_from(x, &self.contact_at(rel, 0.0))
    }

    /// [`TwoBodySystem::true_rates_at`] with the contact at `x` given (`c`, as
    /// [`TwoBodySystem::contact_at`] gives it with no added damping).
    fn true_rates_from(&self, x: &TwoBodyState, c: &Contact) -> ((BodyRate, BodyRate), f64) {
        let ([f_s, f_t], [tau_s, tau_t]) = self.body_wrenches(x, &c.wrench);
        (
            (
                x.servicer.rate(&self.servicer, &f_s, &tau_s),
                x.target.rate(&self.target, &f_t, &tau_t),
            ),
            c.friction_power,
        )
    }

    /// One RK4 step of the true system (rod against walls, no facility) over `h`; returns the
    /// energy friction dissipated over it, J (≥ 0; the friction power integrated with the
    /// step's own RK4 weights).
    pub fn step_rk4(&self, x: &mut TwoBodyState, h: f64) -> f64 {
        let first = self.true_rates_and_friction_power(x);
        self.step_rk4_with(x, &first, h)
    }

    /// [`TwoBodySystem::step_rk4`] with its first stage given (`first`, the rates and friction
    /// power at `x` as [`TwoBodySystem::true_rates_and_friction_power`] gives them): the same
    /// step, to the bit; steps of several widths from one state share their first stage.
    fn step_rk4_with(
        &self,
        x: &mut TwoBodyState,
        first: &((BodyRate, BodyRate), f64),
        h: f64,
    ) -> f64 {
        let advance = |x: &TwoBodyState, r: &(BodyRate, BodyRate), dt: f64| TwoBodyState {
            servicer: x.servicer.advanced(&r.0, dt),
            target: x.target.advanced(&r.1, dt),
        };
        let (k1, p1) = *first;
        let (k2, p2) = self.true_rates_and_friction_power(&advance(x, &k1, 0.5 * h));
        let (k3, p3) = self.true_rates_and_friction_power(&advance(x, &k2, 0.5 * h));
        let (k4, p4) = self.true_rates_and_friction_power(&advance(x, &k3, h));
        let avg = (
            BodyRate::rk4_average(&k1.0, &k2.0, &k3.0, &k4.0),
            BodyRate::rk4_average(&k1.1, &k2.1, &k3.1, &k4.1),
        );
        *x = advance(x, &avg, h);
        -(p1 + 2.0 * p2 + 2.0 * p3 + p4) * h / 6.0
    }

    /// The contact's active set at a state: which walls push on the rod tip
    /// ([`ContactGeometry::active_set`]), and a signature of the shapes' pushing contact points
    /// (which pair and feature makes each), so that it changes whenever a point appears,
    /// vanishes or moves to another feature.
    pub fn active_set(&self, x: &TwoBodyState) -> u64 {
        self.active_set_at(&self.relative_motion(x))
    }

    /// Whether a contact point of the shapes pushes, its material point moving at `v` (`t`,
    /// m/s): the law's normal force there is positive (what the active set counts).
    fn pushes(&self, point: &crate::shapes::ContactPoint, v: &Vector3<f64>) -> bool {
        self.contact
            .law
            .normal_force(point.depth, -v.dot(&point.normal))
            > 0.0
    }

    /// [`TwoBodySystem::active_set`] for a relative motion of the servicer.
    pub fn active_set_at(&self, rel: &RelativeMotion) -> u64 {
        let (tip, tip_velocity) = rel.point_and_velocity(&self.rod_tip);
        let mut set = self.contact.active_set(&tip, &tip_velocity);
        self.for_each_shape_contact(rel, |point| {
            let v = rel.velocity + rel.angular_velocity.cross(&(point.point - rel.position));
            if self.pushes(point, &v) {
                set = set.wrapping_add(point.id);
            }
        });
        set
    }

    /// The free-flight step with shapes: one force-free step over `period` if the rod tip stays
    /// clear of the walls (as without shapes) and no point of the servicer's shapes can reach
    /// the target within the period: every piece farther from the target's than
    /// `1.1·T·(|v| + |ω|·R)` at the faster end ([`crate::shapes::ShapePairs::clear_of`]).
    /// Returns the relative motion at its end if it stepped.
    fn free_flight_with_shapes(
        &self,
        x: &mut TwoBodyState,
        start: &RelativeMotion,
        tip_velocity: &Vector3<f64>,
        period: f64,
    ) -> Option<RelativeMotion> {
        let mut y = *x;
        y.servicer.drift(&self.servicer, period);
        y.target.drift(&self.target, period);
        let end = self.relative_motion(&y);
        if !self.contact.walls.is_empty() {
            let tip = (end.point_velocity(&self.rod_tip) - tip_velocity).norm() * period / 2.0;
            let clear = |m: &RelativeMotion| self.contact.clearance(&m.point(&self.rod_tip));
            let set = self
                .contact
                .active_set(&start.point(&self.rod_tip), tip_velocity);
            if set != 0 || clear(start) <= tip || clear(&end) <= tip {
                return None;
            }
        }
        let r = self.contact.shapes.servicer_extent();
        let speed = |m: &RelativeMotion| m.velocity.norm() + m.angular_velocity.norm() * r;
        let reach = 1.1 * period * speed(start).max(speed(&end));
        if !self.contact.shapes.clear_of(&servicer_pose(start), reach) {
            return None;
        }
        *x = y;
        Some(end)
    }

    /// A lower bound of the smallest gap between the servicer and the target, m (negative in
    /// contact): the rod tip to the walls' planes, and the shapes ([`crate::shapes::ShapePairs::clearance`]).
    pub fn clearance_at(&self, rel: &RelativeMotion) -> f64 {
        let walls = self.contact.clearance(&rel.point(&self.rod_tip));
        if self.contact.shapes.is_empty() {
            walls
        } else {
            walls.min(self.contact.shapes.clearance(&servicer_pose(rel)))
        }
    }

    /// Advances the true system (rod against walls, no facility) by `period`: the ideal
    /// reference's integrator.
    ///
    /// - Free flight: while the rod tip stays clear of every wall over the whole period (both
    ///   ends clear by more than the bend of its path, `|a_tip| T² / 2`), one force-free step.
    /// - Otherwise RK4 with `substeps` steps per period, and every change of the contact's
    ///   active set (a wall starts or stops pushing) located by bisection to `h / 2¹⁶`: an RK4 step
    ///   ends just before it and a step of that width crosses it, so that no step of size
    ///   straddles the kink or jump of the force at contact start and end.
    ///
    /// Returns the energy friction dissipated over the period, J (0 without friction).
    pub fn step_reference(&self, x: &mut TwoBodyState, period: f64, substeps: u32) -> f64 {
        let start = self.relative_motion(x);
        self.step_reference_from(x, &start, period, substeps).0
    }

    /// [`TwoBodySystem::step_reference`] with the relative motion at `x` given (`start`, as
    /// [`TwoBodySystem::relative_motion`] gives it): the same step, to the bit. Also returns the
    /// relative motion at the new state when the step computed it (every step but a free-flight
    /// step with shapes), so that the next step need not compute it again.
    pub fn step_reference_from(
        &self,
        x: &mut TwoBodyState,
        start: &RelativeMotion,
        period: f64,
        substeps: u32,
    ) -> (f64, Option<RelativeMotion>) {
        let (work, end) = self.step_reference_at(x, &self.reference_start(start), period, substeps);
        (work, end.map(|end| end.rel))
    }

    /// What a reference step reads of its start, from the relative motion there.
    pub fn reference_start(&self, rel: &RelativeMotion) -> ReferenceStart {
        let (tip, tip_velocity) = rel.point_and_velocity(&self.rod_tip);
        ReferenceStart {
            rel: *rel,
            tip,
            tip_velocity,
            clearance: None,
            known: None,
        }
    }

    /// [`TwoBodySystem::step_reference_from`] from a [`ReferenceStart`] (the relative motion at
    /// `x` and what is read of it): the same step, to the bit; returns the [`ReferenceStart`] of
    /// the new state when the step computed its relative motion, with what the step knows of
    /// it (after a free-flight step, its clearance), for the next step.
    pub fn step_reference_at(
        &self,
        x: &mut TwoBodyState,
        start: &ReferenceStart,
        period: f64,
        substeps: u32,
    ) -> (f64, Option<ReferenceStart>) {
        let tip_velocity = start.tip_velocity;
        // the active set at `x`, once known
        let mut known = None;
        if !self.contact.shapes.is_empty() {
            if let Some(end) = self.free_flight_with_shapes(x, &start.rel, &tip_velocity, period) {
                // its test kept every piece of the servicer farther from the target's than it
                // can move in the period: no contact point of the shapes at its end
                let end = self.reference_start(&end);
                let known = Some(self.contact_and_active_set_of(&end, false));
                return (0.0, Some(ReferenceStart { known, ..end }));
            }
        } else {
            // without shapes, the active set and the clearance are the rod tip's
            let set = self.contact.active_set(&start.tip, &tip_velocity);
            known = Some(set);
            if set == 0 {
                let mut y = *x;
                BodyState::drift_pair(
                    &mut y.servicer,
                    &self.servicer,
                    &mut y.target,
                    &self.target,
                    period,
                );
                let end = self.reference_start(&self.relative_motion(&y));
                // how far the rod tip's path may stray over the period from what the clearances
                // at its ends show: the bend of its path, |Δv_tip|·T/2
                let bend = (end.tip_velocity - tip_velocity).norm() * period / 2.0;
                let clear_start = start
                    .clearance
                    .unwrap_or_else(|| self.contact.clearance(&start.tip));
                if clear_start > bend {
                    let clear_end = self.contact.clearance(&end.tip);
                    if clear_end > bend {
                        *x = y;
                        let clearance = Some(clear_end);
                        return (0.0, Some(ReferenceStart { clearance, ..end }));
                    }
                }
            }
        }
        let h = period / substeps as f64;
        let mut remaining = period;
        let mut friction_work = 0.0;
        // the relative motion at `x` (a step's end is the next step's start: computed once, for
        // its active set and the next step's first RK4 stage)
        let mut rel = start.rel;
        // the active set at `x` (a step's end is the next step's start: asked once), and the
        // contact there when known (the last active set's pass computed it too)
        let (mut contact, mut before) = match (known, start.known) {
            (Some(set), _) => (None, set),
            (None, Some((c, set))) => (Some(c), set),
            (None, None) => (None, self.active_set_at(&rel)),
        };
        // the end's contact and active set, for the next step
        let mut end_known = None;
        while remaining > period * 1e-12 {
            let step = h.min(remaining);
            // the first RK4 stage at `x`, shared by every step from it (the bisection's too)
            let first = match contact.take() {
                Some(c) => self.true_rates_from(x, &c),
                None => self.true_rates_at(x, &rel),
            };
            let mut y = *x;
            let work = self.step_rk4_with(&mut y, &first, step);
            let mut end = self.reference_start(&self.relative_motion(&y));
            let (end_contact, after) = self.contact_and_active_set(&mut end);
            if after == before {
                *x = y;
                rel = end.rel;
                friction_work += work;
                remaining -= step;
                before = after;
                contact = Some(end_contact);
                end_known = Some((end_contact, after));
                continue;
            }
            end_known = None;
            // the set changes within the step: bisect for the first moment it does
            let (mut lo, mut hi) = (0.0, step);
            for _ in 0..16 {
                let mid = 0.5 * (lo + hi);
                let mut z = *x;
                self.step_rk4_with(&mut z, &first, mid);
                if self.active_set(&z) == before {
                    lo = mid;
                } else {
                    hi = mid;
                }
            }
            // up to the switch with every RK4 stage before it, then across it in a tiny step
            friction_work += self.step_rk4_with(x, &first, lo);
            friction_work += self.step_rk4(x, hi - lo);
            remaining -= hi;
            rel = self.relative_motion(x);
            before = self.active_set_at(&rel);
        }
        let end = ReferenceStart {
            known: end_known,
            ..self.reference_start(&rel)
        };
        (friction_work, Some(end))
    }
}

/// How many units of rounding (`f64::EPSILON`) of the terms of a torque its part across the
/// force may be and still be rounding alone ([`through_centre`]): the compensators' moments are
/// sums of a few products (a measured moment, the moments of a correction and of an amendment),
/// each rounded, and differ from the moment of the force they apply by up to 88 such units on
/// `paper-table1` (every compensator at 4–20 ms; pida and model-mediated up to 30 at 40 ms;
/// `examples/axial_torque_audit.rs`). 2⁷: a line of action within 3e-14 of the lever arms
/// (0.03 pm at 1 m) of the centre. Terms that cancel each other (pic, dac, tdpa-impedance at
/// 40 ms: up to 2200 units) leave more: those bodies turn at rounding level, as they did.
const ROUNDING_UNITS: f64 = 128.0;

/// A body's torque about its centre of mass, `moment + lever` (N·m, world: `moment` the wrench's
/// moment about the sensor origin, `lever` the moment of `force` moved from there to the centre),
/// without its part across the force when that part is rounding alone: when the force's line of
/// action passes through the centre to the precision of the sum that made the torque,
/// `|F × τ|₁ ≤ ROUNDING_UNITS · ε · |F|₁ (|moment|₁ + |lever|₁)`, only the torque along the force
/// (a couple about its own line) is kept: `τ·F / |F|² F`. A contact along an axis through both
/// centres of mass (every axial preset: rod, walls and centres on one line) then turns neither
/// body, as in exact arithmetic, where the terms would cancel exactly but a compensator's moment
/// about the off-axis sensor and the moment of its force differ in their last bits. A torque
/// with no part across the force (zero, a couple about the force's line, or no force at all) is
/// returned as it is, to the bit.
fn through_centre(
    torque: Vector3<f64>,
    force: &Vector3<f64>,
    moment: &Vector3<f64>,
    lever: &Vector3<f64>,
) -> Vector3<f64> {
    if torque == Vector3::zeros() {
        return torque;
    }
    let across = force.cross(&torque).abs().sum();
    let terms = moment.abs().sum() + lever.abs().sum();
    if across > 0.0 && across <= ROUNDING_UNITS * f64::EPSILON * force.abs().sum() * terms {
        force * (torque.dot(force) / force.norm_squared())
    } else {
        torque
    }
}

/// The servicer's body frame in `t` for a relative motion.
fn servicer_pose(rel: &RelativeMotion) -> Isometry3<f64> {
    Isometry3::from_parts(Translation3::from(rel.position), rel.orientation)
}

/// Most surfaces a [`GeometryPrior`] query returns.
pub const PRIOR_SURFACES: usize = 4;

/// The scenario's nominal contact geometry as the compensators' prior for a contact's normal
/// (issue 22): what the scenario states (its walls and shapes, [`crate::plan::Plan::nominal`]),
/// not the facility's true mounting. Built once at plan time; its query is read-only and
/// allocation-free.
#[derive(Debug, Clone, PartialEq)]
pub struct GeometryPrior {
    /// The nominal system (walls, shapes, rod tip).
    pub system: TwoBodySystem,
    /// The servicer's attitude relative to `t` (servicer to `t`) assumed for the shapes where
    /// the robot's measured one is not known ([`GeometryPrior::normals`]; a recording without
    /// it): the scenario's initial one.
    pub orientation: nalgebra::UnitQuaternion<f64>,
    /// Largest nominal clearance (m) at which a wall still counts as touched (the facility's
    /// mounting and the robot's tracking put the measured tip off the nominal wall).
    pub wall_margin: f64,
    /// The nominal friction coefficient (the largest of the scenario's kinetic and static
    /// ones): the cone about a prior normal within which a measured force agrees with it.
    pub friction: f64,
}

impl GeometryPrior {
    /// The nominal contact normals (into the target, unit, `t`) for the rod tip at `tip`
    /// (`t`, m), one per surface, the servicer at [`GeometryPrior::orientation`]
    /// ([`GeometryPrior::normals_at`]). Writes up to [`PRIOR_SURFACES`] normals into `out` and
    /// returns how many. Allocation-free.
    pub fn normals(&self, tip: &Vector3<f64>, out: &mut [Vector3<f64>; PRIOR_SURFACES]) -> usize {
        self.normals_at(tip, &self.orientation, out)
    }

    /// The nominal contact normals (into the target, unit, `t`) for the rod tip at `tip`
    /// (`t`, m) and the servicer at `orientation` (servicer to `t`: the robot's measured
    /// attitude), one per surface: each wall the tip is behind (or within
    /// [`GeometryPrior::wall_margin`] of), and the shapes' contact points (the servicer placed
    /// by `tip` and `orientation`) merged within 10° and force-weighted (the nominal law at the
    /// point's depth, no velocity). Writes up to [`PRIOR_SURFACES`] normals into `out` and
    /// returns how many. Allocation-free.
    pub fn normals_at(
        &self,
        tip: &Vector3<f64>,
        orientation: &nalgebra::UnitQuaternion<f64>,
        out: &mut [Vector3<f64>; PRIOR_SURFACES],
    ) -> usize {
        let mut sums = [Vector3::zeros(); PRIOR_SURFACES];
        let count = self.weighted_normals(tip, orientation, &mut sums);
        for (o, s) in out.iter_mut().zip(&sums).take(count) {
            *o = s.normalize();
        }
        count
    }

    /// The nominal direction of the whole contact's normal force (into the target, unit, `t`)
    /// for the rod tip at `tip` (`t`, m) and the servicer at `orientation` (servicer to `t`):
    /// the weighted sum of every surface's normal ([`GeometryPrior::normals_at`]'s weights), so
    /// that a corner pressing two surfaces gives the direction of their summed normal force, and
    /// how many surfaces (normals more than 10° apart) it sums; `None` where the tip touches no
    /// nominal surface. Allocation-free.
    pub fn contact_normal(
        &self,
        tip: &Vector3<f64>,
        orientation: &nalgebra::UnitQuaternion<f64>,
    ) -> Option<(Vector3<f64>, usize)> {
        let mut sums = [Vector3::zeros(); PRIOR_SURFACES];
        let count = self.weighted_normals(tip, orientation, &mut sums);
        let total: Vector3<f64> = sums[..count].iter().sum();
        (count > 0 && total.norm() > 0.0).then(|| (total.normalize(), count))
    }

    /// The surfaces' normals times their weights (walls: the nominal depth of the tip behind
    /// them, or, when it is behind none, `wall_margin` less its clearance; shapes: the nominal
    /// normal force), merged within 10°, into `sums`; returns how many. Allocation-free.
    fn weighted_normals(
        &self,
        tip: &Vector3<f64>,
        orientation: &nalgebra::UnitQuaternion<f64>,
        sums: &mut [Vector3<f64>; PRIOR_SURFACES],
    ) -> usize {
        let mut count = 0;
        let mut add = |n: Vector3<f64>, w: f64, sums: &mut [Vector3<f64>; PRIOR_SURFACES]| {
            if let Some(s) = sums[..count]
                .iter_mut()
                .find(|s| s.normalize().dot(&n) > 10f64.to_radians().cos())
            {
                *s += n * w;
            } else if count < PRIOR_SURFACES {
                sums[count] = n * w;
                count += 1;
            }
        };
        let walls = &self.system.contact.walls;
        // behind a wall: the walls' depths weigh (a corner's summed normal force); else the
        // walls within the margin, by how near
        let behind = walls.iter().any(|w| w.signed_distance(tip) < 0.0);
        for wall in walls {
            let distance = wall.signed_distance(tip);
            if distance < self.wall_margin {
                let w = if behind {
                    (-distance).max(0.0)
                } else {
                    self.wall_margin - distance
                };
                if w > 0.0 {
                    add(-wall.normal, w, sums);
                }
            }
        }
        if !self.system.contact.shapes.is_empty() {
            let rel = RelativeMotion {
                position: tip - orientation * self.system.rod_tip,
                orientation: *orientation,
                velocity: Vector3::zeros(),
                angular_velocity: Vector3::zeros(),
            };
            self.system
                .for_each_shape_contact_force(&rel, 0.0, |point, force| {
                    let w = force.force.dot(&point.normal);
                    if w > 0.0 {
                        add(-point.normal, w, sums);
                    }
                });
        }
        count
    }
}
