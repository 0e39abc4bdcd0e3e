//! `pida` — Algorithm 3, parameter identification and damping amendment:
//! `F̂_comp = F_comp + F_α` (29), `M̂_comp = M_comp + M_α` (30), with the energy observer fed
//! by `F_comp`. See docs/compensators/pida.md.

use super::delay::{ContactEstimator, ContactView, PRIOR_CONE_MARGIN};
use super::energy::{friction_force, DampingAmendment};
use super::force::{compensate_force, CompensatedWrench};
use super::params::ModelParams;
use super::{Compensator, CompensatorContext, CompensatorInput, CompensatorOutput};
use crate::frames::FrameWrench;
use crate::world::GeometryPrior;
use nalgebra::Vector3;

/// Parameter identification and damping amendment.
#[derive(Debug, Clone)]
pub struct Pida {
    estimator: ContactEstimator,
    amendment: DampingAmendment,
    sensor_origin: Vector3<f64>,
    /// The last tick's contact view and amendment wrench ([`Pida::last_tick`]).
    last: Option<(ContactView, FrameWrench)>,
    /// The scenario's nominal geometry ([`CompensatorContext::geometry`]): a corner's normal at
    /// the virtual tip ([`corner_normal`]).
    geometry: Option<std::sync::Arc<GeometryPrior>>,
}

impl Pida {
    /// A PIDA compensator.
    pub fn new(p: &ModelParams, context: &CompensatorContext) -> Self {
        Pida {
            estimator: ContactEstimator::new(p, context).with_geometry(context.geometry.clone()),
            amendment: DampingAmendment::new(p, context),
            sensor_origin: context.sensor_origin,
            last: None,
            geometry: context.geometry.clone(),
        }
    }

    /// The last tick's contact view (the normal, μ̂, k̂, ĉ in use) and the energy
    /// controller's wrench `(F_α, M_α)` (N, N·m), for diagnostics (`examples/pida_presets.rs`);
    /// `None` before the first tick.
    pub fn last_tick(&self) -> Option<(ContactView, FrameWrench)> {
        self.last
    }
}

/// The compensated wrench with its friction predicted at the virtual tip: the normal part of
/// `F_comp` kept, `F_n = max(F_comp·n̂, 0)`, and the tangential part replaced by the friction
/// the identified coefficient μ̂ gives at the virtual tip's sliding velocity,
/// [`friction_force`]`(μ̂, F_n·n̂, v_des, n̂)` (N, on the frame, along the virtual sliding);
/// the moment moved by the change of force acting at the virtual tip, `(p_des − p_s) × ΔF`.
///
/// The measured friction follows the robot's sliding, `τ` late: where the virtual tip's sliding
/// slows, stops or turns, it acted in the wrong direction with the wrong size (on
/// `oblique-6dof` at μ 0.3, 65-71° off the virtual sliding in the second collision; see
/// docs/compensators/pida.md, "Friction and corners"). The predicted friction is also the one
/// the energy observer books as real dissipation, so only the normal part's error is left to
/// the observer.
fn virtual_friction(
    comp: &CompensatedWrench,
    friction: f64,
    normal: &Vector3<f64>,
    input: &CompensatorInput,
    sensor_origin: &Vector3<f64>,
) -> CompensatedWrench {
    let f_normal = normal * comp.force.dot(normal).max(0.0);
    let force = f_normal + friction_force(friction, &f_normal, &input.tip_velocity_desired, normal);
    let change = force - comp.force;
    CompensatedWrench {
        force,
        moment: comp.moment + (input.tip_position_desired - sensor_origin).cross(&change),
        error: comp.error + change,
    }
}

/// The friction of [`virtual_friction`] made to follow the normal force the virtual dynamics
/// really feel, `F_n + F_α·n̂` (the amendment's damping `F_α` acts along the normal: while it
/// dissipates the delay's energy in the rebound it cancels much of `F_n`, and friction at the
/// full `μ̂·F_n` then slowed the virtual sliding with almost no normal force, dissipating 58 mJ
/// against the reference's 31 mJ in `probe-drogue`'s first collision at 20 ms): the tangential
/// part becomes [`friction_force`]`(μ̂, max(F_n + F_α·n̂, 0)·n̂, v_des, n̂)`, the moment moved by
/// the change acting at the virtual tip. The energy observer books the friction it is given as
/// real and sums only the rest, so its energy does not change.
fn net_friction(
    comp: &CompensatedWrench,
    alpha: &crate::frames::FrameWrench,
    friction: f64,
    normal: &Vector3<f64>,
    input: &CompensatorInput,
    sensor_origin: &Vector3<f64>,
) -> CompensatedWrench {
    let f_n = comp.force.dot(normal).max(0.0);
    let f_net = (f_n + alpha.force.dot(normal).min(0.0)).max(0.0);
    let v = &input.tip_velocity_desired;
    let change = friction_force(friction, &(normal * f_net), v, normal)
        - friction_force(friction, &(normal * f_n), v, normal);
    CompensatedWrench {
        force: comp.force + change,
        moment: comp.moment + (input.tip_position_desired - sensor_origin).cross(&change),
        error: comp.error + change,
    }
}

/// The friction ratio the robot's contact shows at this tick, `|F_t|/F_n` of `F_act` about the
/// normal in use (0 where `F_n ≤ 0`), for a frictional contact whose coefficient μ̂ is not yet
/// identified (μ̂ rests on sliding samples of the robot, which the compression of a contact
/// often has none of). Without it the measured tangential force, scaled with the normal one,
/// reached the virtual dynamics as it came: the robot's friction from its own sliding, a delay
/// late, which on `rod-in-frame` at 20 ms pushed the virtual tip sideways (0.3 → 8 mm/s across
/// the normal in collision 3, 43 % rebound error). With it the friction acts along the virtual
/// tip's sliding ([`virtual_friction`]) and is booked as real dissipation. Only on a scenario
/// with friction (one with a geometry prior, [`CompensatorContext::geometry`]): on frictionless
/// walls a spinning servicer can make a contact look leaning, and its force's tangential part
/// is noise there (`model_mediated.rs`' random 6-DOF cases, whose fallback is `pida`, moved by
/// it: one rebound 5.02 % off against a 5 % bound).
fn measured_friction(view: &ContactView) -> f64 {
    let f_n = view.force.dot(&view.normal);
    if f_n <= 0.0 {
        return 0.0;
    }
    (view.force - view.normal * f_n).norm() / f_n
}

/// The normal of a corner (two surfaces pressed at once, [`ContactView::corner`]) at the
/// **virtual** tip: the direction of the nominal summed normal force there
/// ([`GeometryPrior::contact_normal`] at `p_des` and the robot's attitude), where the compensated
/// force is rendered, in place of the one at the identification sample (the robot's tip `τ_p`
/// ago), while the virtual tip is in the corner too and that normal lies within the nominal
/// friction cone (plus [`PRIOR_CONE_MARGIN`]) of `normal`; else `normal`. Entering a corner,
/// the split between its surfaces changes within the contact: on `rod-in-frame`'s first
/// collision (the rod's side along the front bar into the side bar) the virtual tip, `τ_r`
/// ahead, already presses the side bar harder, and the sample's normal put the normal force
/// 1.6° off on average (up to 6.5°) in the wrong direction, which turned the servicer (angular
/// velocity 12.8 % off) and made a 15.4 % rebound error at 10 ms (now 2.8 %).
fn corner_normal(
    normal: &Vector3<f64>,
    geometry: &GeometryPrior,
    input: &CompensatorInput,
) -> Vector3<f64> {
    let orientation = input.orientation_actual.unwrap_or(geometry.orientation);
    let cone = (geometry.friction.atan() + PRIOR_CONE_MARGIN).cos();
    match geometry.contact_normal(&input.tip_position_desired, &orientation) {
        Some((n, surfaces)) if surfaces > 1 && n.dot(normal) >= cone => n,
        _ => *normal,
    }
}

impl Compensator for Pida {
    fn step(&mut self, input: &CompensatorInput) -> CompensatorOutput {
        let mut view = self.estimator.step(input); // steps 1-4
        let mut comp = compensate_force(&view, input, &self.sensor_origin); // steps 5-6
        if view.frictional && view.friction <= 0.0 && self.geometry.is_some() {
            view.friction = measured_friction(&view);
        }
        if view.corner {
            if let Some(g) = self.geometry.as_deref() {
                view.normal = corner_normal(&view.normal, g, input);
            }
        }
        let friction = view.frictional && view.friction > 0.0;
        if friction {
            comp = virtual_friction(
                &comp,
                view.friction,
                &view.normal,
                input,
                &self.sensor_origin,
            );
        }
        let alpha = self.amendment.step(&view, &comp.force, input); // steps 7-10
        if friction && !view.corner {
            comp = net_friction(
                &comp,
                &alpha,
                view.friction,
                &view.normal,
                input,
                &self.sensor_origin,
            );
        }
        self.last = Some((view, alpha));
        self.amendment
            .output(&comp.force, &comp.moment, &alpha, &view) // (29), (30)
    }

    fn reset(&mut self) {
        self.estimator.reset();
        self.amendment.reset();
        self.last = None;
    }

    fn estimates_contact(&self) -> bool {
        true
    }

    fn observes_energy(&self) -> bool {
        true
    }
}
