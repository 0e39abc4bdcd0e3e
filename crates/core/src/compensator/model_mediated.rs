//! `model-mediated` — model-mediated rendering with online identification of the contact's
//! geometry and law. See docs/compensators/model-mediated.md.
//!
//! The virtual dynamics feel an identified model of the contact evaluated at the *virtual*
//! rod tip, from the moment the virtual tip reaches an identified surface; the robot,
//! `τ` behind, then reproduces the ideal motion `τ` later and produces the ideal force, late.
//! The measured force identifies the model and, through its residual against the model at
//! the robot's own (aligned) pose, corrects what the model gets wrong:
//! ```text
//! f_s(d, ḋ)      the law of surface s (linear k·d + c·ḋ, or Hunt-Crossley dⁿ(k + c·ḋ))
//! d_s(p)         = max(0, −(p − p_s)·n_s)                 penetration of surface s
//! F_m(p, v)      = −Σ_s f_s(d_s(p), −v·n_s)·n_s            model force on the frame
//! r              = F_mea(k) − F_m(p_act(k−τ_p), v_act(k−τ_p))  residual (in physical contact)
//! F              = F_m(p_des, v_des) + r + F_α             applied force
//! M              = (p_des − p_s0) × F + M_mea − (p_then − p_s0) × (F_m(then) + r)
//! ```
//! `F_α` dissipates what the residual, a delayed force, injects: the residual's work on the
//! virtual motion is observed over each contact (the force held over the step, as the `work`
//! observer does) and, while positive, a damping along the contact normal takes it out,
//! at most `force_ratio_max` times the applied force; what it cannot take in one tick it
//! carries to the next.
//!
//! A contact belongs to a surface when its force direction is within `match_angle` of the
//! surface's normal and the robot is within `gap_tolerance` of it; a contact that no surface
//! explains (every first contact without a prior) is handled by an internal `pida`, stepped at
//! every tick so that its state is current. The model changes only between contacts (the
//! updated surfaces are adopted once the virtual tip is outside them), so an update never
//! makes a force step. A modelled contact during which the robot measures no force at all
//! drops the surface (a phantom). No allocation per tick: the samples' buffer is allocated
//! once.
//!
//! With `prior_shapes` the scenario's shapes are part of the model: while the virtual servicer's
//! shapes touch the target's, their contact wrench at the virtual pose is the engine's own
//! ([`TwoBodySystem::contact_at`] on the nominal shapes) with the model's law and friction: the
//! scenario's (`geometry-and-law`), the calibration's, or fitted at each contact's end on the
//! nominal contact points at the robot's pose (`ShapeModel::fit`); a contact the model
//! rendered stays open until the robot, one loop delay later, has made it too.

use nalgebra::{Matrix2, Matrix3, Matrix4, UnitQuaternion, Vector2, Vector3, Vector4};

use super::detect::ContactDetector;
use super::params::{LawForm, ModelMediatedParams, PriorShapes};
use super::pida::Pida;
use super::surface::{CornerFit, SurfaceFit, SLIDE_SPEED};
use super::{
    Compensator, CompensatorContext, CompensatorInput, CompensatorOutput, ContactEstimate,
    Rendering,
};
use crate::calibration::CalibratedSurface;
use crate::contact::{ContactLaw, ContactModel, Friction, HuntCrossley, LinearSpringDamper, Wall};
use crate::delay_line::DelayLine;
use crate::frames::{FrameWrench, RelativeMotion};
use crate::world::TwoBodySystem;

/// A calibrated surface is contradicted by a contact whose plane lies farther from it than
/// this many of its standard deviations (plus [`CALIBRATION_FLOOR`]) at the contact.
pub const CALIBRATION_TRUST_SIGMAS: f64 = 4.0;
/// The online fit's own accuracy, m: a contact's plane within this (and the calibration's
/// uncertainty) of a calibrated surface agrees with it.
pub const CALIBRATION_FLOOR: f64 = 5e-5;
/// A contact's stiffness more than this share (plus the calibration's relative uncertainty
/// times [`CALIBRATION_TRUST_SIGMAS`]) away from a calibrated law's contradicts it.
pub const CALIBRATION_STIFFNESS_TOLERANCE: f64 = 0.1;
/// A contact's damping time `c/k` (s) more than this share of the calibrated law's (plus
/// [`CALIBRATION_DAMPING_FLOOR`] and the calibration's σ of c times
/// [`CALIBRATION_TRUST_SIGMAS`], over k) away from it contradicts the calibration.
pub const CALIBRATION_DAMPING_TOLERANCE: f64 = 0.2;
/// The online fit's own accuracy of the damping time `c/k` of the linear law, s (2 ms: 377
/// N·s/m on paper-table1's 188 N/mm, a damping ratio of 0.025; with 0.25 ms a single contact's
/// fit under 0.2 N of noise contradicted paper-exp-1.93hz's calibrated c = 130 N·s/m, and
/// its own law rendered the later contacts 2–6 % slow).
pub const CALIBRATION_DAMPING_FLOOR: f64 = 2e-3;
/// The same for Hunt-Crossley's `c/k`, s/m (0.5 s/m: 1 % of the force at 20 mm/s).
pub const CALIBRATION_DAMPING_FLOOR_HUNT_CROSSLEY: f64 = 0.5;

/// A contact `pida` handled has its rebound set to the fitted law's only when the two
/// changes of the normal velocity differ by at most this share of the law's (beyond it the
/// contact is not the one-dimensional one the restoration accounts for).
pub const RESTORE_LIMIT: f64 = 0.2;
/// ... and only when the normal impulse turns the bodies little: `|K·n − (nᵀK·n)·n|` at most
/// this share of `nᵀK·n`.
pub const RESTORE_COUPLING: f64 = 0.05;
/// ... and by more than this share (within it, `pida`'s rebound is as good as the fit's).
pub const RESTORE_DEADBAND: f64 = 0.01;

/// Most surfaces the compensator models.
pub const MAX_SURFACES: usize = 8;
/// Most samples of one contact the Hunt-Crossley fit uses (evenly strided).
pub const HUNT_CROSSLEY_SAMPLES: usize = 200;
/// Most Levenberg-Marquardt iterations of the Hunt-Crossley fit.
pub const HUNT_CROSSLEY_ITERATIONS: usize = 40;
/// Newton iterations of a contact's normal fit under friction ([`SurfaceFit::fit`]).
pub const NORMAL_FIT_ITERATIONS: usize = 20;
/// Regularisation velocity of the rendered friction, m/s: the engine's default `v_ε`
/// (`[contact.friction] stick_velocity`); below it the rendered friction is viscous.
pub const FRICTION_STICK_VELOCITY: f64 = 1e-3;
/// Longest a contact in which the model rendered the shapes stays open after the virtual shapes
/// let go while the robot has not touched yet, s ([`ModelMediated`]'s shapes prior): longer
/// than any loop delay the compensator is meant for.
pub const SHAPES_HOLD: f64 = 0.5;
/// Hunt-Crossley is kept by `auto` when its RMS residual is below this share of the linear
/// fit's.
pub const HUNT_CROSSLEY_PREFERENCE: f64 = 0.7;

/// A modelled contact surface.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Surface {
    /// The plane: point (m) and unit normal into free space, target frame.
    pub wall: Wall,
    /// Its own identified law; `None` for a prior not touched yet (it uses the shared law).
    pub law: Option<ContactModel>,
    /// Contact samples behind the estimate (0 for a prior or a calibrated surface).
    pub weight: f64,
    /// Identified Coulomb friction coefficient μ̂ (0: frictionless, or not identified),
    /// rendered against the virtual tip's sliding velocity.
    pub friction: f64,
    /// The calibration behind it and its uncertainty (`compensator.calibration`), until a
    /// contact contradicts it.
    pub calibrated: Option<CalibratedSurface>,
}

/// One identification sample: a measured force and the robot kinematics that produced it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Sample {
    /// Measured force on the frame, `t`, N.
    pub force: Vector3<f64>,
    /// Robot rod tip `τ_p` earlier, `t`, m.
    pub position: Vector3<f64>,
    /// Robot rod-tip velocity `τ_p` earlier, `t`, m/s.
    pub velocity: Vector3<f64>,
}

/// A surface and law fitted to one contact's samples.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Fit {
    /// The plane, point (m) and normal into free space.
    pub wall: Wall,
    /// The law.
    pub law: ContactModel,
    /// Coulomb friction coefficient μ̂ of the sliding samples (0: the contact's force does not
    /// lean from its normal, [`SurfaceFit::leans`]).
    pub friction: f64,
    /// RMS of the force residual, N.
    pub rms: f64,
    /// Samples used.
    pub samples: usize,
}

/// How the current contact is rendered.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Mode {
    /// No contact.
    Free,
    /// The identified model at the virtual tip, plus the residual.
    Model,
    /// The internal `pida` (the model does not explain the contact).
    Fallback,
}

/// Model-mediated rendering with online identification.
#[derive(Debug, Clone)]
pub struct ModelMediated {
    params: ModelMediatedParams,
    fallback: Pida,
    detector: ContactDetector,
    period: f64,
    delay_ticks: usize,
    sensor_origin: Vector3<f64>,
    /// Robot tip position and velocity of the last `τ_p/T + 1` ticks.
    kinematics: DelayLine<(Vector3<f64>, Vector3<f64>)>,
    started: bool,
    surfaces: [Option<Surface>; MAX_SURFACES],
    /// The law of the latest identified contact, for surfaces without their own.
    shared_law: Option<ContactModel>,
    /// The friction coefficient of the latest identified contact, for surfaces without a law
    /// of their own (the same materials as far as the model knows).
    shared_friction: f64,
    /// Surface updates waiting for the virtual tip to leave the model.
    pending: [Option<Surface>; MAX_SURFACES],
    /// Shared-law update waiting likewise.
    pending_law: Option<ContactModel>,
    /// Shared friction update waiting likewise.
    pending_friction: Option<f64>,
    /// This contact's samples (capacity `max_samples`, allocated once).
    samples: Vec<Sample>,
    /// Sum of this contact's measured forces, N (its mean direction).
    force_sum: Vector3<f64>,
    mode: Mode,
    /// Ticks of this contact with the robot in physical contact.
    physical_ticks: usize,
    /// The first two modelled surfaces the robot's tip was behind at once in this contact (a
    /// corner, an edge): the contact is split between them ([`CornerFit`]).
    corner: Option<(usize, usize)>,
    /// The surface the model rendered in this contact, if one.
    rendered: Option<usize>,
    /// Energy the residual (and its damping) put into the virtual motion in this contact, J.
    residual_energy: f64,
    /// Residual plus damping force held over the last step, and the velocity then.
    previous: Option<(Vector3<f64>, Vector3<f64>)>,
    /// The surfaces and shared law a run starts with (priors, calibration).
    initial_surfaces: [Option<Surface>; MAX_SURFACES],
    initial_law: Option<ContactModel>,
    /// Whether a calibration gave the initial model.
    calibrated: bool,
    /// With a calibration: ticks a modelled contact stays open after the virtual tip left the
    /// model (the calibrated robot delay, the sensor delay and two ticks), so that the robot,
    /// that much behind, reaches the surface before the contact is judged; 0 without.
    hold_ticks: usize,
    /// Ticks since the virtual tip was last inside the model, in this contact.
    since_model: usize,
    /// Impulse the model applied to the virtual dynamics in this contact, `Σ T·F` (on the
    /// frame, `t`), N·s: taken back if the robot never felt the contact (a phantom).
    model_impulse: Vector3<f64>,
    /// An impulse to take back at this tick (N·s, on the frame), applied through the
    /// velocity correction `K·J`.
    undo: Option<Vector3<f64>>,
    /// How far past the rendered surface the robot went in this contact (m, its penetration
    /// less the surface's band: [`CALIBRATION_TRUST_SIGMAS`] σ plus [`CALIBRATION_FLOOR`]).
    robot_past: f64,
    /// Why `pida` has the current contact (in [`Mode::Fallback`]).
    reason: Rendering,
    /// Normals of the surfaces dropped as phantoms (a contact contradicted them).
    contradicted: [Option<Vector3<f64>>; MAX_SURFACES],
    /// Impulse `pida` applied to the virtual dynamics in this contact, `Σ T·F` (on the frame,
    /// `t`), N·s.
    fallback_impulse: Vector3<f64>,
    /// A contact `pida` handled, fitted: its normal (into free space), the incoming speed
    /// along it (m/s, [`ModelMediated::approach`]'s), the fitted law and `pida`'s impulse; the
    /// virtual rebound is set to the law's at this tick.
    restore: Option<(Vector3<f64>, f64, ContactModel, Vector3<f64>)>,
    /// The virtual tip's velocity at this contact's first tick, before any contact force was
    /// applied to it, `t`, m/s: the velocity the robot, replaying the virtual motion one delay
    /// later, meets the surface with. (The robot's reported velocity is not used: over EGM and
    /// RSI it is 17-25 mm/s off, and a 20 mm/s approach read as 25 mm/s made every later
    /// contact rebound 50 % fast.)
    approach: Vector3<f64>,
    /// The scenario's shapes as prior geometry (`prior_shapes`), rendered by the engine's
    /// shape query; `None` without.
    shapes: Option<ShapeModel>,
}

impl ModelMediated {
    /// A model-mediated compensator (allocates its samples' buffer once).
    pub fn new(p: &ModelMediatedParams, context: &CompensatorContext) -> Self {
        let (surfaces, initial_law) = initial_model(p);
        ModelMediated {
            params: p.clone(),
            // the model renders from its own prior walls; its fallback without the geometry prior
            fallback: Pida::new(
                &p.fallback,
                &CompensatorContext {
                    geometry: None,
                    ..context.clone()
                },
            ),
            detector: ContactDetector::new(p.fallback.contact_force, context.period),
            period: context.period,
            delay_ticks: context.sensor_delay_ticks,
            sensor_origin: context.sensor_origin,
            kinematics: DelayLine::new(
                context.sensor_delay_ticks,
                (Vector3::zeros(), Vector3::zeros()),
            ),
            started: false,
            surfaces,
            shared_law: initial_law,
            shared_friction: p.prior_friction,
            pending: [None; MAX_SURFACES],
            pending_law: None,
            pending_friction: None,
            samples: Vec::with_capacity(p.max_samples as usize),
            force_sum: Vector3::zeros(),
            mode: Mode::Free,
            physical_ticks: 0,
            corner: None,
            rendered: None,
            residual_energy: 0.0,
            previous: None,
            initial_surfaces: surfaces,
            initial_law,
            calibrated: initial_law.is_some(),
            hold_ticks: match p.calibration.check() {
                Ok(c) if !p.calibration.is_empty() => {
                    (c.robot_delay / context.period).round() as usize
                        + context.sensor_delay_ticks
                        + 2
                }
                _ => 0,
            },
            since_model: 0,
            model_impulse: Vector3::zeros(),
            undo: None,
            robot_past: 0.0,
            reason: Rendering::PidaNoPrior,
            contradicted: [None; MAX_SURFACES],
            fallback_impulse: Vector3::zeros(),
            restore: None,
            approach: Vector3::zeros(),
            shapes: ShapeModel::new(p, context, initial_law),
        }
    }

    /// Why a force that no surface explains (frame convention, at the robot's tip) is
    /// `pida`'s: no surface faces it; one does but no law is known yet; or one does (or did,
    /// until a contact contradicted it) but the robot met the force away from it.
    fn fallback_reason(&self, force: &Vector3<f64>) -> Rendering {
        let cos_max = self.params.match_angle.to_radians().cos();
        let direction = -force.normalize();
        let facing = |normal: &Vector3<f64>| direction.dot(normal) >= cos_max;
        let mut reason = Rendering::PidaNoPrior;
        for s in self.surfaces.iter().flatten() {
            if facing(&s.wall.normal) {
                if self.law_of(s).is_none() {
                    return Rendering::PidaLawUnknown;
                }
                reason = Rendering::PidaPriorContradicted;
            }
        }
        if self.contradicted.iter().flatten().any(facing) {
            reason = Rendering::PidaPriorContradicted;
        }
        reason
    }

    /// The modelled surfaces (prior, identified or both).
    pub fn surfaces(&self) -> impl Iterator<Item = &Surface> {
        self.surfaces.iter().flatten()
    }

    /// The law a surface is rendered with, if it has one.
    fn law_of(&self, s: &Surface) -> Option<ContactModel> {
        s.law.or(self.shared_law)
    }

    /// The friction coefficient a surface is rendered with: its own with its own law, else
    /// the shared one (the latest contact's).
    fn friction_of(&self, s: &Surface) -> f64 {
        if s.law.is_some() {
            s.friction
        } else {
            self.shared_friction
        }
    }

    /// Model force on the rod at a tip pose (`t`, N): the sum over the surfaces penetrated of
    /// each one's normal law and its friction `μ̂` against the tip's sliding velocity
    /// (`v_t = v − (v·n)·n`, regularised Coulomb as the engine's [`Friction`]); and the index
    /// of the deepest surface penetrated (any surface with a law whose plane the tip is
    /// behind).
    fn model_force(
        &self,
        tip: &Vector3<f64>,
        velocity: &Vector3<f64>,
    ) -> (Vector3<f64>, Option<usize>) {
        let mut force = Vector3::zeros();
        let mut deepest: Option<(usize, f64)> = None;
        for (i, s) in self.surfaces.iter().enumerate() {
            let Some(s) = s else { continue };
            let Some(law) = self.law_of(s) else { continue };
            let d = s.wall.penetration(tip);
            if d > 0.0 {
                let f_n = law.normal_force(d, s.wall.penetration_rate(velocity));
                force += s.wall.normal * f_n;
                let mu = self.friction_of(s);
                if mu > 0.0 {
                    // the engine's regularised Coulomb law against the sliding velocity
                    let v_t = velocity - s.wall.normal * velocity.dot(&s.wall.normal);
                    force += Friction {
                        static_coefficient: mu,
                        kinetic_coefficient: mu,
                        stick_velocity: FRICTION_STICK_VELOCITY,
                        stribeck_velocity: FRICTION_STICK_VELOCITY,
                    }
                    .force(f_n, &v_t);
                }
                if deepest.is_none_or(|(_, dd)| d > dd) {
                    deepest = Some((i, d));
                }
            }
        }
        (force, deepest.map(|(i, _)| i))
    }

    /// Whether the robot's tip is inside a calibrated surface's band of uncertainty
    /// ([`CALIBRATION_TRUST_SIGMAS`] standard deviations plus [`CALIBRATION_FLOOR`] outside its
    /// plane): a rendered contact does not end (nor is it taken for a phantom) while the robot,
    /// its reported position noisy, may still be reaching the surface.
    fn near_calibrated(&self, tip: &Vector3<f64>) -> bool {
        self.surfaces.iter().flatten().any(|s| {
            s.calibrated.is_some_and(|c| {
                let band = CALIBRATION_TRUST_SIGMAS * c.sigma_at(tip) + CALIBRATION_FLOOR;
                s.wall.signed_distance(tip) < band
            })
        })
    }

    /// The surface that explains a measured force (frame convention) at the robot's tip:
    /// normal within `match_angle` of the force's reaction, tip within `gap_tolerance`.
    fn explaining_surface(&self, force: &Vector3<f64>, tip: &Vector3<f64>) -> Option<usize> {
        let cos_max = self.params.match_angle.to_radians().cos();
        let direction = -force.normalize(); // the reaction on the rod: along the normal
        let mut best: Option<(usize, f64)> = None;
        for (i, s) in self.surfaces.iter().enumerate() {
            let Some(s) = s else { continue };
            if self.law_of(s).is_none() {
                continue;
            }
            let cos = direction.dot(&s.wall.normal);
            let clearance = (tip - s.wall.point).dot(&s.wall.normal);
            if cos >= cos_max
                && clearance <= self.params.gap_tolerance
                && best.is_none_or(|(_, c)| cos > c)
            {
                best = Some((i, cos));
            }
        }
        best.map(|(i, _)| i)
    }

    /// Ends a contact: fits its samples and queues the surface update.
    fn end_contact(&mut self) {
        if self.physical_ticks == 0 {
            // the model rendered a contact the robot never felt: a phantom surface
            if let (Some(i), true) = (self.rendered, self.params.correct_priors) {
                self.contradicted[i] = self.surfaces[i].map(|s| s.wall.normal);
                self.surfaces[i] = None;
                self.pending[i] = None;
                // and, if the robot went past it and felt nothing, its impulse is taken back:
                // the virtual bodies go on towards the real surface as if the phantom had not
                // been rendered, the robot reaches it and that contact (pida's) corrects the
                // model. A contact that ended before the robot got there (shorter than the
                // loop's delay) is not judged so
                if self.model_impulse != Vector3::zeros() && self.robot_past > 0.0 {
                    self.undo = Some(self.model_impulse);
                }
            }
        } else if self.samples.len() >= self.params.min_samples as usize
            && !self.fit_shapes()
            && !self.split_corner()
        {
            // with a calibration, `auto` fits the calibrated law's form (measured at leisure)
            let form = match (self.params.law, self.initial_law) {
                (LawForm::Auto, Some(ContactModel::Linear(_))) if self.calibrated => {
                    LawForm::Linear
                }
                (LawForm::Auto, Some(ContactModel::HuntCrossley(_))) if self.calibrated => {
                    LawForm::HuntCrossley
                }
                (form, _) => form,
            };
            if let Some(fit) = fit_contact(&self.samples, &self.force_sum, form) {
                if self.mode == Mode::Fallback && self.params.correct_priors {
                    // pida's rebound is not the contact's: the fitted law's is restored
                    // the robot replays the virtual motion: it meets the surface with the
                    // virtual tip's velocity before the contact's first force
                    let normal = fit.wall.normal;
                    let speed_in = -self.approach.dot(&normal);
                    if speed_in > 0.0 {
                        self.restore = Some((normal, speed_in, fit.law, self.fallback_impulse));
                    }
                }
                let n = self.samples.len() as f64;
                let centre = self
                    .samples
                    .iter()
                    .fold(Vector3::zeros(), |c, x| c + x.position / n);
                self.merge(fit, &centre);
            }
        }
        self.samples.clear();
        self.force_sum = Vector3::zeros();
        self.physical_ticks = 0;
        self.corner = None;
        self.rendered = None;
        self.residual_energy = 0.0;
        self.previous = None;
        self.model_impulse = Vector3::zeros();
        self.fallback_impulse = Vector3::zeros();
        self.robot_past = 0.0;
        self.mode = Mode::Free;
        if let Some(sh) = self.shapes.as_mut() {
            sh.motions.clear();
            sh.rendered = false;
            sh.robot_touched = false;
        }
    }

    /// Whether a contact in which the model rendered the shapes stays open (the virtual shapes
    /// apart, no force measured): until the robot, replaying the virtual motion one loop delay
    /// later, has made that contact too (its shapes at `motion_then`, the robot's motion behind
    /// this measurement, touched and are apart again), at most [`SHAPES_HOLD`] after the
    /// virtual shapes let go. Without it a contact shorter than the loop's delay would end
    /// before the robot's began, and the robot's would be taken for a new one (`pida`'s).
    /// `robot_touching`: the robot's shapes touch at this tick ([`ModelMediated::robot_touching`]).
    fn shapes_hold(&self, robot_touching: bool) -> bool {
        let limit = (SHAPES_HOLD / self.period).round() as usize;
        match self.shapes.as_ref() {
            Some(sh) if sh.rendered => {
                robot_touching || (!sh.robot_touched && self.since_model < limit)
            }
            _ => false,
        }
    }

    /// Whether the robot's shapes touch (nominally) at its motion behind this measurement, in a
    /// contact where the model rendered the shapes (else false, not queried); remembered for
    /// the contact ([`ModelMediated::shapes_hold`]).
    fn robot_touching(&mut self, motion_then: Option<&RelativeMotion>) -> bool {
        match (self.shapes.as_mut(), motion_then) {
            (Some(sh), Some(m)) if sh.rendered => {
                let touching = sh.touching(m);
                sh.robot_touched |= touching;
                touching
            }
            _ => false,
        }
    }

    /// A contact the robot's shapes made (the shapes prior): their law and friction fitted
    /// ([`ShapeModel::fit`]) and queued. Returns whether the contact was the shapes' (then it
    /// is not fitted as a plane).
    fn fit_shapes(&mut self) -> bool {
        let (min, memory) = (self.params.min_samples as usize, self.params.memory as f64);
        match self.shapes.as_mut() {
            Some(sh) if sh.motions.len() == self.samples.len() => {
                sh.fit(&self.samples, min, memory)
            }
            _ => false,
        }
    }

    /// A contact that pressed two modelled surfaces at once (`corner`): its samples split
    /// between their laws and friction by [`CornerFit`] (their geometry kept: the prior's or
    /// the identified one), each surface's update queued with its own linear law and μ̂, and
    /// the first one's as the shared law. Returns whether it did (false: no corner, a
    /// Hunt-Crossley law asked for, or the samples do not determine the split; the contact is
    /// then fitted as one surface).
    fn split_corner(&mut self) -> bool {
        let Some((a, b)) = self.corner else {
            return false;
        };
        if self.params.law == LawForm::HuntCrossley {
            return false;
        }
        let (Some(sa), Some(sb)) = (
            self.pending[a].or(self.surfaces[a]),
            self.pending[b].or(self.surfaces[b]),
        ) else {
            return false;
        };
        let mut fit = CornerFit::new(
            [-sa.wall.normal, -sb.wall.normal],
            [sa.wall.point, sb.wall.point],
        );
        for x in &self.samples {
            fit.add(&x.force, &x.position, &x.velocity);
        }
        let Some(split) = fit.fit() else {
            return false;
        };
        if split
            .iter()
            .any(|w| !(w.stiffness > 0.0 && w.stiffness.is_finite()))
        {
            return false;
        }
        let law = |i: usize| {
            ContactModel::Linear(LinearSpringDamper {
                stiffness: split[i].stiffness,
                damping: split[i].damping.max(0.0),
            })
        };
        for (i, (slot, old)) in [(a, sa), (b, sb)].into_iter().enumerate() {
            let friction = split[i].friction.max(0.0);
            self.pending[slot] = Some(match old.calibrated {
                // a calibrated surface keeps its law (measured at leisure) and learns its
                // friction (a calibration has none)
                Some(_) => Surface { friction, ..old },
                None => Surface {
                    law: Some(law(i)),
                    friction,
                    ..old
                },
            });
        }
        if sa.calibrated.is_none() {
            self.pending_law = Some(law(0));
        }
        self.pending_friction = Some(split[0].friction.max(0.0));
        true
    }

    /// Merges a contact's fit into the surface it belongs to (or a new one): queued, adopted
    /// once the virtual tip is outside it.
    fn merge(&mut self, fit: Fit, centre: &Vector3<f64>) {
        self.pending_law = Some(fit.law);
        self.pending_friction = Some(fit.friction);
        let cos_max = self.params.match_angle.to_radians().cos();
        let matched = (0..MAX_SURFACES)
            .filter_map(|i| {
                let s = self.pending[i].or(self.surfaces[i])?;
                Some((i, s, s.wall.normal.dot(&fit.wall.normal)))
            })
            .filter(|(_, _, cos)| *cos >= cos_max)
            .max_by(|a, b| a.2.total_cmp(&b.2));
        let new_weight = fit.samples as f64;
        if let Some((i, old, _)) = matched {
            if let Some(calibrated) = old.calibrated {
                if agrees(&calibrated, old.law.or(self.shared_law), &fit, centre) {
                    // the calibration, measured at leisure, knows better than one contact;
                    // its friction (a calibration has none) is the contacts'
                    if fit.friction > 0.0 {
                        self.pending[i] = Some(Surface {
                            friction: fit.friction,
                            ..old
                        });
                    }
                    return;
                }
                // contradicted: corrected by this contact below, as a prior is
            }
        }
        if let (Some((i, old, _)), false) = (matched, self.params.correct_priors) {
            if old.weight == 0.0 {
                // a prior kept as given: only its law (and friction) is learned
                self.pending[i] = Some(Surface {
                    law: Some(fit.law),
                    friction: fit.friction,
                    ..old
                });
                return;
            }
        }
        let surface = match matched {
            Some((_, old, _)) if old.weight > 0.0 => {
                // sample-weighted mean of the past (capped) and the new fit
                let w_old = old.weight.min(self.params.memory as f64);
                let total = w_old + new_weight;
                let normal = (old.wall.normal * w_old + fit.wall.normal * new_weight).normalize();
                let offset = (old.wall.point.dot(&normal) * w_old
                    + fit.wall.point.dot(&normal) * new_weight)
                    / total;
                Surface {
                    wall: Wall {
                        point: normal * offset,
                        normal,
                    },
                    law: Some(match (old.law, fit.law) {
                        (Some(a), b) => blend_laws(&a, w_old, &b, new_weight),
                        (None, b) => b,
                    }),
                    weight: total,
                    friction: (old.friction * w_old + fit.friction * new_weight) / total,
                    calibrated: None,
                }
            }
            // a prior (weight 0) is replaced by the first fit
            _ => Surface {
                wall: fit.wall,
                law: Some(fit.law),
                weight: new_weight,
                friction: fit.friction,
                calibrated: None,
            },
        };
        let slot = matched.map(|(i, _, _)| i).or_else(|| {
            (0..MAX_SURFACES).find(|&i| self.surfaces[i].is_none() && self.pending[i].is_none())
        });
        let slot = slot.unwrap_or_else(|| {
            // all slots taken: replace the surface with the least evidence
            (0..MAX_SURFACES)
                .min_by(|&a, &b| {
                    let w = |i: usize| self.surfaces[i].map_or(0.0, |s| s.weight);
                    w(a).total_cmp(&w(b))
                })
                .unwrap_or(0)
        });
        self.pending[slot] = Some(surface);
    }

    /// Adopts the queued updates (surfaces and shared law) together, once the virtual tip is
    /// outside every modelled surface both before and after: the model then never changes
    /// under the virtual tip (no force step).
    fn adopt_pending(&mut self, tip: &Vector3<f64>) {
        if self.pending.iter().all(Option::is_none)
            && self.pending_law.is_none()
            && self.pending_friction.is_none()
        {
            return;
        }
        let inside = |surfaces: &[Option<Surface>; MAX_SURFACES], shared: Option<ContactModel>| {
            surfaces
                .iter()
                .flatten()
                .any(|s| s.law.or(shared).is_some() && s.wall.penetration(tip) > 0.0)
        };
        let mut next = self.surfaces;
        for (slot, p) in next.iter_mut().zip(&self.pending) {
            if p.is_some() {
                *slot = *p;
            }
        }
        let next_law = self.pending_law.or(self.shared_law);
        if !inside(&self.surfaces, self.shared_law) && !inside(&next, next_law) {
            self.surfaces = next;
            self.shared_law = next_law;
            self.shared_friction = self.pending_friction.unwrap_or(self.shared_friction);
            self.pending = [None; MAX_SURFACES];
            self.pending_law = None;
            self.pending_friction = None;
        }
    }

    /// The estimate reported: the law of the surface being rendered, else the shared law.
    fn estimate(&self) -> Option<ContactEstimate> {
        let shapes = self
            .shapes
            .as_ref()
            .filter(|sh| sh.rendered && sh.known)
            .map(|sh| sh.system.contact.law);
        let law = shapes
            .or_else(|| {
                self.rendered
                    .and_then(|i| self.surfaces[i])
                    .and_then(|s| self.law_of(&s))
            })
            .or(self.shared_law)?;
        Some(match law {
            ContactModel::Linear(l) => ContactEstimate {
                stiffness: l.stiffness,
                damping: l.damping,
            },
            ContactModel::HuntCrossley(h) => ContactEstimate {
                stiffness: h.stiffness,
                damping: h.damping,
            },
        })
    }
}

/// Whether a contact's fit agrees with a calibrated surface: its plane within
/// [`CALIBRATION_TRUST_SIGMAS`] standard deviations plus [`CALIBRATION_FLOOR`] of the
/// calibrated one at the contact (`centre`, m), and its stiffness (a law of the same form)
/// within [`CALIBRATION_STIFFNESS_TOLERANCE`] plus the calibration's own uncertainty, and its
/// damping time `c/k` within [`CALIBRATION_DAMPING_TOLERANCE`] plus
/// [`CALIBRATION_DAMPING_FLOOR`] (linear; [`CALIBRATION_DAMPING_FLOOR_HUNT_CROSSLEY`]) plus the
/// calibration's own uncertainty.
fn agrees(
    calibrated: &CalibratedSurface,
    law: Option<ContactModel>,
    fit: &Fit,
    centre: &Vector3<f64>,
) -> bool {
    // the fitted plane's point nearest the contact, against the calibrated plane
    let on_fit = centre - fit.wall.normal * fit.wall.signed_distance(centre);
    let offset = calibrated.wall.signed_distance(&on_fit);
    let tolerance = CALIBRATION_TRUST_SIGMAS * calibrated.sigma_at(centre) + CALIBRATION_FLOOR;
    let stiffness = |l: &ContactModel| match l {
        ContactModel::Linear(l) => (l.stiffness, 1.0, l.damping),
        ContactModel::HuntCrossley(h) => (h.stiffness, h.exponent, h.damping),
    };
    let law_agrees = match law {
        Some(l) => {
            let ((k_cal, n_cal, c_cal), (k_fit, n_fit, c_fit)) =
                (stiffness(&l), stiffness(&fit.law));
            let damping_time = c_cal / k_cal;
            let floor = match l {
                ContactModel::Linear(_) => CALIBRATION_DAMPING_FLOOR,
                ContactModel::HuntCrossley(_) => CALIBRATION_DAMPING_FLOOR_HUNT_CROSSLEY,
            };
            // laws of different forms are compared at the contact's scale only by the plane
            (n_cal - n_fit).abs() > 0.25
                || ((k_fit / k_cal - 1.0).abs()
                    <= CALIBRATION_STIFFNESS_TOLERANCE
                        + CALIBRATION_TRUST_SIGMAS * calibrated.stiffness_relative_sigma
                    && (c_fit / k_fit - damping_time).abs()
                        <= CALIBRATION_DAMPING_TOLERANCE * damping_time
                            + floor
                            + CALIBRATION_TRUST_SIGMAS * calibrated.damping_sigma / k_cal)
        }
        None => true,
    };
    offset.abs() <= tolerance && law_agrees
}

/// The surfaces and the shared law a run starts with: the calibration's walls with its law,
/// then the prior walls (without a law of their own); the shared law is the calibration's.
fn initial_model(
    p: &ModelMediatedParams,
) -> ([Option<Surface>; MAX_SURFACES], Option<ContactModel>) {
    let mut surfaces = prior_surfaces(p);
    let Ok(calibration) = p.calibration.check() else {
        return (surfaces, None);
    };
    // the calibration first: priors beyond the free slots give way
    let mut calibrated = [None; MAX_SURFACES];
    for (slot, c) in calibrated.iter_mut().zip(&calibration.surfaces) {
        *slot = Some(Surface {
            wall: c.wall,
            law: Some(calibration.law),
            weight: 0.0,
            friction: p.prior_friction,
            calibrated: Some(*c),
        });
    }
    let priors = surfaces.iter().flatten().copied().collect::<Vec<_>>();
    surfaces = calibrated;
    let free: Vec<usize> = (0..MAX_SURFACES)
        .filter(|&i| surfaces[i].is_none())
        .collect();
    for (i, prior) in free.into_iter().zip(priors) {
        surfaces[i] = Some(prior);
    }
    (surfaces, Some(calibration.law))
}

/// The prior walls as surfaces without a law of their own (the plan has checked them; a
/// zero normal, which it refuses, is skipped).
fn prior_surfaces(p: &ModelMediatedParams) -> [Option<Surface>; MAX_SURFACES] {
    let mut surfaces = [None; MAX_SURFACES];
    for (slot, w) in surfaces.iter_mut().zip(&p.prior_walls) {
        let normal = Vector3::from(w.normal);
        if normal.norm() > 0.0 {
            *slot = Some(Surface {
                wall: Wall {
                    point: Vector3::from(w.point),
                    normal: normal.normalize(),
                },
                law: None,
                weight: 0.0,
                friction: 0.0,
                calibrated: None,
            });
        }
    }
    surfaces
}

/// Sample-weighted mean of two laws of the same form; a different form: the newer.
fn blend_laws(a: &ContactModel, wa: f64, b: &ContactModel, wb: f64) -> ContactModel {
    let mean = |x: f64, y: f64| (x * wa + y * wb) / (wa + wb);
    match (a, b) {
        (ContactModel::Linear(a), ContactModel::Linear(b)) => {
            ContactModel::Linear(LinearSpringDamper {
                stiffness: mean(a.stiffness, b.stiffness),
                damping: mean(a.damping, b.damping),
            })
        }
        (ContactModel::HuntCrossley(a), ContactModel::HuntCrossley(b)) => {
            ContactModel::HuntCrossley(HuntCrossley {
                stiffness: mean(a.stiffness, b.stiffness),
                damping: mean(a.damping, b.damping),
                exponent: mean(a.exponent, b.exponent),
            })
        }
        (_, b) => *b,
    }
}

/// The rebound speed (m/s) of a mass `mass` (kg) meeting a surface of law `law` at
/// `speed_in` (m/s, > 0) along its normal: `m·d̈ = −f(d, ḋ)` from `d = 0`, `ḋ = speed_in`,
/// integrated (RK4, about 400 steps over the contact) until the surface lets go (`d ≤ 0`, or
/// no force while moving out). At most `speed_in`: the laws never create energy.
pub fn rebound_speed(law: &ContactModel, mass: f64, speed_in: f64) -> f64 {
    if !(mass > 0.0 && speed_in > 0.0) {
        return speed_in.max(0.0);
    }
    // time scale: the undamped penetration d_max = ((n+1)·m·v²/(2k))^(1/(n+1)) over v
    let (k, n) = match law {
        ContactModel::Linear(l) => (l.stiffness, 1.0),
        ContactModel::HuntCrossley(h) => (h.stiffness, h.exponent),
    };
    if !(k > 0.0) {
        return speed_in;
    }
    let d_max = ((n + 1.0) * mass * speed_in * speed_in / (2.0 * k)).powf(1.0 / (n + 1.0));
    let dt = d_max / speed_in / 100.0;
    let accel = |d: f64, rate: f64| -law.normal_force(d.max(0.0), rate) / mass;
    let (mut d, mut rate) = (0.0, speed_in);
    for _ in 0..20_000 {
        let (k1d, k1v) = (rate, accel(d, rate));
        let (k2d, k2v) = (
            rate + 0.5 * dt * k1v,
            accel(d + 0.5 * dt * k1d, rate + 0.5 * dt * k1v),
        );
        let (k3d, k3v) = (
            rate + 0.5 * dt * k2v,
            accel(d + 0.5 * dt * k2d, rate + 0.5 * dt * k2v),
        );
        let (k4d, k4v) = (rate + dt * k3v, accel(d + dt * k3d, rate + dt * k3v));
        d += dt / 6.0 * (k1d + 2.0 * k2d + 2.0 * k3d + k4d);
        rate += dt / 6.0 * (k1v + 2.0 * k2v + 2.0 * k3v + k4v);
        if d <= 0.0 || (rate < 0.0 && law.normal_force(d, rate) == 0.0) {
            break;
        }
    }
    (-rate).clamp(0.0, speed_in)
}

/// Fits a plane and a law to one contact's samples: the normal is the mean reaction's
/// direction, `n̂ = −ΣF/|ΣF|`, unless friction leans the force from the surface's normal
/// ([`frictional_normal`]: then the normal is the fitted one and μ̂ is fitted too); along it `f = −F·n̂`, `s = p·n̂`, `ḋ = −v·n̂`, and the law's
/// parameters and the plane's offset `h` (penetration `d = h − s`) by least squares. `None`
/// if the samples do not determine a law that pushes (k ≤ 0).
pub fn fit_contact(samples: &[Sample], force_sum: &Vector3<f64>, form: LawForm) -> Option<Fit> {
    if samples.len() < 3 || force_sum.norm() == 0.0 {
        return None;
    }
    let (normal, friction) = match frictional_normal(samples) {
        Some((n, mu)) => (-n, mu),
        None => (-force_sum.normalize(), 0.0),
    };
    fit_along(samples, &normal, form).map(|fit| Fit { friction, ..fit })
}

/// Under friction, the contact's normal (into the wall) and friction coefficient: the normal
/// by [`SurfaceFit`] (the one along which the law explains the samples best), and μ̂ by least
/// squares over the samples sliding faster than [`SLIDE_SPEED`] against the law it is rendered
/// with (`F_t·ŝ = μ·F_n·s/√(s² + v_ε²)`, `v_ε` = [`FRICTION_STICK_VELOCITY`]). `None` when the force does not lean from that normal
/// ([`SurfaceFit::leans`]: a frictionless contact, whose fit is then exactly the mean force's).
pub fn frictional_normal(samples: &[Sample]) -> Option<(Vector3<f64>, f64)> {
    let mut surface = SurfaceFit::default();
    for x in samples {
        surface.add(&x.force, &x.position, &x.velocity);
    }
    let (normal, _) = surface.fit(NORMAL_FIT_ITERATIONS);
    if !surface.leans() {
        return None;
    }
    // μ̂ by least squares against the law it is rendered with, the regularised Coulomb law:
    // F_t·ŝ = μ·F_n·g(s), g(s) = s/√(s² + v_ε²), over the samples that slide and push
    let (mut num, mut den) = (0.0, 0.0);
    for x in samples {
        let f_n = x.force.dot(&normal);
        let v_t = x.velocity - normal * x.velocity.dot(&normal);
        let speed = v_t.norm();
        if f_n <= 0.0 || speed <= SLIDE_SPEED {
            continue;
        }
        let g = speed / (speed * speed + FRICTION_STICK_VELOCITY * FRICTION_STICK_VELOCITY).sqrt();
        let f_t = x.force - normal * f_n;
        num += f_t.dot(&(v_t / speed)) * f_n * g;
        den += (f_n * g).powi(2);
    }
    let mu = if den > 0.0 { (num / den).max(0.0) } else { 0.0 };
    Some((normal, mu))
}

/// Fits the plane and the law along the given normal (into free space), friction 0.
fn fit_along(samples: &[Sample], normal: &Vector3<f64>, form: LawForm) -> Option<Fit> {
    let normal = *normal;
    let linear = fit_linear(samples, &normal);
    match form {
        LawForm::Linear => linear,
        LawForm::HuntCrossley => fit_hunt_crossley(samples, &normal, linear.as_ref()),
        LawForm::Auto => match (linear, fit_hunt_crossley(samples, &normal, linear.as_ref())) {
            (Some(l), Some(h)) if h.rms < HUNT_CROSSLEY_PREFERENCE * l.rms => Some(h),
            (Some(l), _) => Some(l),
            (None, h) => h,
        },
    }
}

/// Linear law: `f = k·(h − s) + c·ḋ` = `a − k·s + c·ḋ` with `a = k·h`, least squares on
/// centred regressors; a negative `c` is refitted with `c = 0` (a law that never creates
/// energy).
fn fit_linear(samples: &[Sample], normal: &Vector3<f64>) -> Option<Fit> {
    let n = samples.len() as f64;
    let (mut s_mean, mut r_mean) = (0.0, 0.0);
    for x in samples {
        s_mean += x.position.dot(normal) / n;
        r_mean += -x.velocity.dot(normal) / n;
    }
    // f = a' − k·(s − s̄) + c·(ḋ − ḋ̄)
    let mut a = Matrix3::zeros();
    let mut b = Vector3::zeros();
    let mut a2 = Matrix2::zeros();
    let mut b2 = Vector2::zeros();
    for x in samples {
        let f = -x.force.dot(normal);
        let row = Vector3::new(
            1.0,
            -(x.position.dot(normal) - s_mean),
            -x.velocity.dot(normal) - r_mean,
        );
        a += row * row.transpose();
        b += row * f;
        let row2 = Vector2::new(row[0], row[1]);
        a2 += row2 * row2.transpose();
        b2 += row2 * f;
    }
    let (a0, k, c) = match a.cholesky().map(|ch| ch.solve(&b)) {
        Some(th) if th[2] >= 0.0 => (th[0], th[1], th[2]),
        _ => {
            let th = a2.cholesky()?.solve(&b2);
            (th[0], th[1], 0.0)
        }
    };
    if !(k > 0.0 && k.is_finite() && a0.is_finite()) {
        return None;
    }
    // a' = k·(h − s̄) + c·ḋ̄  ⇒  h = s̄ + (a' − c·ḋ̄)/k
    let h = s_mean + (a0 - c * r_mean) / k;
    let law = ContactModel::Linear(LinearSpringDamper {
        stiffness: k,
        damping: c,
    });
    Some(finish_fit(samples, normal, h, law))
}

/// The fit's plane `p·n̂ = h` as a wall and its RMS force residual.
fn finish_fit(samples: &[Sample], normal: &Vector3<f64>, h: f64, law: ContactModel) -> Fit {
    let wall = Wall {
        point: normal * h,
        normal: *normal,
    };
    let mut sq = 0.0;
    for x in samples {
        let d = wall.penetration(&x.position);
        let model = if d > 0.0 {
            law.normal_force(d, wall.penetration_rate(&x.velocity))
        } else {
            0.0
        };
        sq += (-x.force.dot(normal) - model).powi(2);
    }
    Fit {
        wall,
        law,
        friction: 0.0,
        rms: (sq / samples.len() as f64).sqrt(),
        samples: samples.len(),
    }
}

/// Hunt-Crossley law `f = dⁿ·(k + c·ḋ)`, `d = h − s`: Levenberg-Marquardt on (h, ln k, c/k, n)
/// from the start `n = 1.5`, `h` just beyond the sample that pressed least. `None` if it does
/// not converge to a law that pushes.
fn fit_hunt_crossley(
    samples: &[Sample],
    normal: &Vector3<f64>,
    linear: Option<&Fit>,
) -> Option<Fit> {
    // residuals f_i − dᵢⁿ·k·(1 + q·ḋᵢ) with θ = (h, ln k, q = c/k, n), on at most
    // HUNT_CROSSLEY_SAMPLES samples (evenly strided): the fit's time stays bounded
    let stride = samples.len().div_ceil(HUNT_CROSSLEY_SAMPLES).max(1);
    let fitted = || samples.iter().step_by(stride);
    let data = |x: &Sample| {
        (
            -x.force.dot(normal),
            x.position.dot(normal),
            -x.velocity.dot(normal),
        )
    };
    let (mut s_least, mut f_least, mut f_most) = (0.0, f64::INFINITY, 0.0_f64);
    let mut s_min = f64::INFINITY;
    for x in fitted() {
        let (f, s, _) = data(x);
        if f < f_least {
            (f_least, s_least) = (f, s);
        }
        f_most = f_most.max(f);
        s_min = s_min.min(s);
    }
    // depth scale: the samples' spread along the normal
    let depth = fitted()
        .map(|x| data(x).1 - s_min)
        .fold(0.0, f64::max)
        .max(1e-9);
    let n0 = 1.5;
    let h0 = match linear {
        Some(l) => l
            .wall
            .point
            .dot(normal)
            .min(s_least + 0.05 * depth)
            .max(s_least),
        None => s_least,
    }
    .max(s_min + 1e-3 * depth);
    let d_max = (h0 - s_min).max(1e-12);
    let k0 = f_most / d_max.powf(n0);
    let mut theta = Vector4::new(h0, k0.ln(), 0.0, n0);
    let cost = |t: &Vector4<f64>| {
        let mut sq = 0.0;
        for x in fitted() {
            let (f, s, rate) = data(x);
            let d = (t[0] - s).max(0.0);
            sq += (f - d.powf(t[3]) * t[1].exp() * (1.0 + t[2] * rate)).powi(2);
        }
        sq
    };
    let mut current = cost(&theta);
    let mut lambda = 1e-3;
    for _ in 0..HUNT_CROSSLEY_ITERATIONS {
        let mut jtj = Matrix4::zeros();
        let mut jtr = Vector4::zeros();
        for x in fitted() {
            let (f, s, rate) = data(x);
            let d = (theta[0] - s).max(0.0);
            if d <= 0.0 {
                continue; // no force predicted here: no gradient
            }
            let k = theta[1].exp();
            let dn = d.powf(theta[3]);
            let g = 1.0 + theta[2] * rate;
            let model = dn * k * g;
            let r = f - model;
            // ∂model/∂θ
            let j = Vector4::new(theta[3] * model / d, model, dn * k * rate, model * d.ln());
            jtj += j * j.transpose();
            jtr += j * r;
        }
        let mut improved = false;
        for _ in 0..10 {
            let mut damped = jtj;
            for i in 0..4 {
                damped[(i, i)] *= 1.0 + lambda;
                damped[(i, i)] += 1e-30;
            }
            let Some(ch) = damped.cholesky() else {
                lambda *= 10.0;
                continue;
            };
            let mut next = theta + ch.solve(&jtr);
            next[3] = next[3].clamp(0.5, 3.0);
            let c = cost(&next);
            if c.is_finite() && c < current {
                let gain = (current - c) / current.max(1e-300);
                theta = next;
                current = c;
                lambda = (lambda * 0.3).max(1e-12);
                improved = gain > 1e-12;
                break;
            }
            lambda *= 10.0;
        }
        if !improved {
            break;
        }
    }
    let (h, k, q, n) = (theta[0], theta[1].exp(), theta[2], theta[3]);
    if !(k.is_finite() && k > 0.0 && h.is_finite() && q.is_finite()) {
        return None;
    }
    let law = ContactModel::HuntCrossley(HuntCrossley {
        stiffness: k,
        damping: (k * q).max(0.0),
        exponent: n,
    });
    Some(finish_fit(samples, normal, h, law))
}

/// The scenario's shapes as the model's prior geometry (`prior_shapes`, issue 22): the nominal
/// system's shapes (its walls left out: they are the planes' part of the model) rendered at the
/// virtual servicer pose by the engine's own contact query ([`TwoBodySystem::contact_at`]: the
/// same shape pairs and point law as the reference), with the law and friction the model has
/// for them. Everything is allocated once, at construction.
#[derive(Debug, Clone)]
struct ShapeModel {
    /// The nominal system with the rendered law and friction in its contact (walls removed).
    system: TwoBodySystem,
    /// Whether a law is known (the prior's, the calibration's or an identified one).
    known: bool,
    /// Whether the law and friction are the scenario's, kept as given (`geometry-and-law`).
    fixed: bool,
    /// Whether the law is a calibration's, kept as given (only μ̂ is learned).
    calibrated: bool,
    /// Samples behind the identified law (0: a prior).
    weight: f64,
    /// The identified friction coefficient μ̂ rendered (regularised Coulomb, static = kinetic);
    /// unused with `fixed`.
    friction: f64,
    /// The state a run starts with: known, law, friction.
    initial: (bool, ContactModel, f64),
    /// An update (law, μ̂, weight) waiting for the virtual shapes to be apart.
    pending: Option<(ContactModel, f64, f64)>,
    /// The robot's attitude (servicer to `t`) and angular velocity (`t`, rad/s, from successive
    /// attitudes) of the last `τ_p/T + 1` ticks.
    attitudes: DelayLine<(UnitQuaternion<f64>, Vector3<f64>)>,
    /// The robot's attitude at the last tick, if reported.
    last_attitude: Option<UnitQuaternion<f64>>,
    /// The robot's motion behind each of this contact's samples (capacity `max_samples`).
    motions: Vec<RelativeMotion>,
    /// Whether the shapes were rendered in this contact.
    rendered: bool,
    /// Whether the robot's shapes touched (nominally) in this contact.
    robot_touched: bool,
}

impl ShapeModel {
    /// The shapes prior of `p` (`None` for `prior_shapes = "none"` or without the scenario's
    /// geometry in `context`); `calibrated_law` is the calibration's law, if one.
    fn new(
        p: &ModelMediatedParams,
        context: &CompensatorContext,
        calibrated_law: Option<ContactModel>,
    ) -> Option<Self> {
        let geometry = context.geometry.as_ref()?;
        if p.prior_shapes == PriorShapes::None || geometry.system.contact.shapes.is_empty() {
            return None;
        }
        let mut system = geometry.system.clone();
        system.contact.walls.clear();
        system.sensor_origin = context.sensor_origin;
        let fixed = p.prior_shapes == PriorShapes::GeometryAndLaw;
        let (known, law) = match (fixed, calibrated_law) {
            (true, _) => (true, system.contact.law),
            (false, Some(law)) => (true, law),
            (false, None) => (false, system.contact.law),
        };
        let mut model = ShapeModel {
            system,
            known,
            fixed,
            calibrated: !fixed && calibrated_law.is_some(),
            weight: 0.0,
            friction: p.prior_friction,
            initial: (known, law, p.prior_friction),
            pending: None,
            attitudes: DelayLine::new(
                context.sensor_delay_ticks,
                (UnitQuaternion::identity(), Vector3::zeros()),
            ),
            last_attitude: None,
            motions: Vec::with_capacity(p.max_samples as usize),
            rendered: false,
            robot_touched: false,
        };
        model.set(law, p.prior_friction);
        Some(model)
    }

    /// Renders `law` and, unless the scenario's friction is kept, μ̂ `friction`.
    fn set(&mut self, law: ContactModel, friction: f64) {
        self.system.contact.law = law;
        if !self.fixed {
            self.friction = friction;
            self.system.contact.shape_friction.clear(); // no allocation: it only shrinks
            self.system.contact.friction = (friction > 0.0).then_some(Friction {
                static_coefficient: friction,
                kinetic_coefficient: friction,
                stick_velocity: FRICTION_STICK_VELOCITY,
                stribeck_velocity: FRICTION_STICK_VELOCITY,
            });
        }
    }

    /// Forgets the run (no allocation).
    fn reset(&mut self) {
        let (known, law, friction) = self.initial;
        self.known = known;
        self.weight = 0.0;
        self.set(law, friction);
        self.pending = None;
        self.attitudes
            .fill((UnitQuaternion::identity(), Vector3::zeros()));
        self.last_attitude = None;
        self.motions.clear();
        self.rendered = false;
        self.robot_touched = false;
    }

    /// Records the robot's attitude of this tick (its angular velocity from the last one).
    fn push_attitude(&mut self, attitude: Option<UnitQuaternion<f64>>, period: f64) {
        let Some(q) = attitude else {
            self.last_attitude = None;
            return;
        };
        let omega = match self.last_attitude {
            Some(last) => (q * last.inverse()).scaled_axis() / period,
            None => {
                self.attitudes.fill((q, Vector3::zeros()));
                Vector3::zeros()
            }
        };
        self.last_attitude = Some(q);
        self.attitudes.push((q, omega));
    }

    /// The robot's servicer motion `lag` ticks ago from its rod tip then (`t`, m, m/s).
    fn robot_motion(
        &self,
        lag: usize,
        tip: &Vector3<f64>,
        tip_velocity: &Vector3<f64>,
    ) -> Option<RelativeMotion> {
        self.last_attitude?;
        let (orientation, angular_velocity) = self.attitudes.delayed(lag);
        let arm = orientation * self.system.rod_tip;
        Some(RelativeMotion {
            position: tip - arm,
            orientation,
            velocity: tip_velocity - angular_velocity.cross(&arm),
            angular_velocity,
        })
    }

    /// The model's wrench on the frame (N, N·m about the sensor origin) at a servicer motion,
    /// `None` where the shapes do not push (apart, or no law known).
    fn wrench(&self, motion: &RelativeMotion) -> Option<FrameWrench> {
        if !self.known {
            return None;
        }
        let c = self.system.contact_at(motion, 0.0);
        (c.force != Vector3::zeros()).then_some(c.wrench)
    }

    /// Whether the shapes touch (any contact point) at a servicer motion.
    fn touching(&self, motion: &RelativeMotion) -> bool {
        let mut any = false;
        self.system.for_each_shape_contact(motion, |_| any = true);
        any
    }

    /// Adopts a queued update once the virtual shapes are apart.
    fn adopt_pending(&mut self, motion: &RelativeMotion) {
        if let Some((law, friction, weight)) = self.pending {
            if !self.touching(motion) {
                self.set(law, friction);
                self.known = true;
                self.weight = weight;
                self.pending = None;
            }
        }
    }

    /// Fits the shapes' law and friction to a contact's samples (`samples[i]` measured with the
    /// robot at `self.motions[i]`) and queues the update: with the nominal geometry every
    /// sample's contact points are known, so the force on the servicer is linear in the law,
    /// `−F = Σᵢ (k·dᵢ + c·ḋᵢ)·nᵢ + μ·Σᵢ φ(f_n,i, v_t,i)` (φ the engine's regularised Coulomb law
    /// at μ = 1): (k, c) by least squares over the force's components with the friction of the
    /// last estimate taken off, then μ by least squares over the sliding samples (a point
    /// sliding faster than [`SLIDE_SPEED`]), three rounds. The calibration's law is kept (only
    /// μ̂ learned); the scenario's (`geometry-and-law`) is kept as given. Returns whether the
    /// contact was the shapes' (`min_samples` samples with the robot's shapes touching).
    fn fit(&mut self, samples: &[Sample], min_samples: usize, memory: f64) -> bool {
        let touching = self.motions.iter().filter(|m| self.touching(m)).count();
        if touching < min_samples || touching < samples.len() / 2 {
            return false;
        }
        if self.fixed {
            return true;
        }
        let unit = Friction {
            static_coefficient: 1.0,
            kinetic_coefficient: 1.0,
            stick_velocity: FRICTION_STICK_VELOCITY,
            stribeck_velocity: FRICTION_STICK_VELOCITY,
        };
        let calibrated = self.calibrated.then_some(self.system.contact.law);
        let mut law = calibrated.unwrap_or(self.system.contact.law);
        let mut mu = 0.0;
        for _ in 0..3 {
            // (k, c) with μ's friction taken off (a calibrated law: kept)
            if calibrated.is_none() {
                let (mut a, mut b) = (Matrix2::<f64>::zeros(), Vector2::<f64>::zeros());
                for (x, m) in samples.iter().zip(&self.motions) {
                    let (mut basis_k, mut basis_c, mut friction) =
                        (Vector3::zeros(), Vector3::zeros(), Vector3::zeros());
                    self.for_each_point(m, |n, d, v| {
                        let rate = -v.dot(n);
                        basis_k += n * d;
                        basis_c += n * rate;
                        if mu > 0.0 {
                            let f_n = law.normal_force(d, rate);
                            friction += unit.force(f_n, &(v - n * v.dot(n))) * mu;
                        }
                    });
                    let target = -x.force - friction;
                    let rows = [basis_k, basis_c];
                    for i in 0..2 {
                        b[i] += rows[i].dot(&target);
                        for j in 0..2 {
                            a[(i, j)] += rows[i].dot(&rows[j]);
                        }
                    }
                }
                let Some(kc) = a.try_inverse().map(|inv| inv * b) else {
                    return true;
                };
                if !(kc[0] > 0.0 && kc[0].is_finite()) {
                    return true;
                }
                law = ContactModel::Linear(LinearSpringDamper {
                    stiffness: kc[0],
                    damping: kc[1].max(0.0),
                });
            }
            // μ over the sliding samples
            let (mut num, mut den) = (0.0, 0.0);
            for (x, m) in samples.iter().zip(&self.motions) {
                let (mut normal, mut friction, mut sliding) =
                    (Vector3::zeros(), Vector3::zeros(), false);
                self.for_each_point(m, |n, d, v| {
                    let f_n = law.normal_force(d, -v.dot(n));
                    let v_t = v - n * v.dot(n);
                    normal += n * f_n;
                    friction += unit.force(f_n, &v_t);
                    sliding |= v_t.norm() > SLIDE_SPEED;
                });
                if sliding {
                    num += (-x.force - normal).dot(&friction);
                    den += friction.norm_squared();
                }
            }
            mu = if den > 0.0 {
                (num / den).max(0.0)
            } else {
                self.friction
            };
        }
        let n = touching as f64;
        let (law, friction, weight) = if self.weight > 0.0 && calibrated.is_none() {
            let w_old = self.weight.min(memory);
            (
                blend_laws(&self.system.contact.law, w_old, &law, n),
                (self.friction * w_old + mu * n) / (w_old + n),
                w_old + n,
            )
        } else {
            (law, mu, n)
        };
        self.pending = Some((law, friction, weight));
        true
    }

    /// Calls `f(n, d, v)` for every contact point of the shapes at a servicer motion: its
    /// normal (into free space), depth (m) and the servicer's material velocity there (m/s).
    fn for_each_point(
        &self,
        motion: &RelativeMotion,
        mut f: impl FnMut(&Vector3<f64>, f64, &Vector3<f64>),
    ) {
        self.system.for_each_shape_contact(motion, |p| {
            let v = motion.velocity + motion.angular_velocity.cross(&(p.point - motion.position));
            f(&p.normal, p.depth, &v);
        });
    }
}

impl Compensator for ModelMediated {
    fn step(&mut self, input: &CompensatorInput) -> CompensatorOutput {
        let (f_mea, m_mea) = (input.measured.force, input.measured.moment);
        let (p_act, v_act) = (input.tip_position_actual, input.tip_velocity_actual);
        let (p_des, v_des) = (input.tip_position_desired, input.tip_velocity_desired);
        if !self.started {
            self.kinematics.fill((p_act, v_act));
            self.started = true;
        }
        self.kinematics.push((p_act, v_act));
        // the robot kinematics that produced this measurement
        let (p_then, v_then) = self.kinematics.delayed(self.delay_ticks);
        let physical = self.detector.update(&f_mea);
        let fallback = self.fallback.step(input); // kept current at every tick
                                                  // the shapes prior: the robot's servicer motion that produced this measurement, and the
                                                  // model's wrench at the virtual motion
        let (delay_ticks, period) = (self.delay_ticks, self.period);
        let motion_then = self.shapes.as_mut().and_then(|sh| {
            sh.push_attitude(input.orientation_actual, period);
            sh.robot_motion(delay_ticks, &p_then, &v_then)
        });

        if self.mode == Mode::Free {
            self.adopt_pending(&p_des);
            if let (Some(sh), Some(m)) = (self.shapes.as_mut(), input.motion_desired.as_ref()) {
                sh.adopt_pending(m);
            }
        }
        let (rod_des, surface_des) = self.model_force(&p_des, &v_des);
        let (rod_then, _) = self.model_force(&p_then, &v_then);
        let shape_des = match (self.shapes.as_ref(), input.motion_desired.as_ref()) {
            (Some(sh), Some(m)) => sh.wrench(m),
            _ => None,
        };
        let model_des = surface_des.is_some() || shape_des.is_some();
        let model_then = rod_then != Vector3::zeros();

        let robot_touching = self.robot_touching(motion_then.as_ref());
        // a contact starts with the first force or model contact, ends when neither is left
        if self.mode == Mode::Free && (physical || model_des) {
            self.approach = v_des;
            self.mode = if model_des {
                Mode::Model
            } else {
                match self.explaining_surface(&f_mea, &p_then) {
                    Some(_) => Mode::Model,
                    None => {
                        // the robot's shapes touching, their law not known yet
                        let shapes_unknown = match (self.shapes.as_ref(), motion_then.as_ref()) {
                            (Some(sh), Some(m)) => !sh.known && sh.touching(m),
                            _ => false,
                        };
                        self.reason = if shapes_unknown {
                            Rendering::PidaLawUnknown
                        } else {
                            self.fallback_reason(&f_mea)
                        };
                        Mode::Fallback
                    }
                }
            };
        } else if self.mode != Mode::Free
            && !physical
            && !model_des
            && !model_then
            && !self.near_calibrated(&p_then)
            && self.since_model >= self.hold_ticks
            && !self.shapes_hold(robot_touching)
        {
            self.end_contact();
        }
        self.since_model = if model_des { 0 } else { self.since_model + 1 };
        let shapes_rendered = self.shapes.as_ref().is_some_and(|sh| sh.rendered);
        if self.mode == Mode::Model
            && physical
            && !model_then
            && !shapes_rendered
            && shape_des.is_none()
            && self.explaining_surface(&f_mea, &p_then).is_none()
        {
            // a force that no surface explains (none there): `pida` takes the contact. A force
            // that a surface explains but at the wrong level stays with the model (handing a
            // contact to `pida` midway loses more than it saves; see the doc page). What the
            // model applied so far was wrong: its impulse is taken back
            self.mode = Mode::Fallback;
            self.reason = Rendering::PidaPriorContradicted;
            if self.model_impulse != Vector3::zeros() {
                self.undo = Some(self.model_impulse);
                self.model_impulse = Vector3::zeros();
            }
        }

        if self.mode != Mode::Free && physical {
            self.physical_ticks += 1;
            if self.corner.is_none() {
                // two modelled surfaces pressed at once by the robot
                let mut behind = (0..MAX_SURFACES).filter(|&i| {
                    self.surfaces[i].is_some_and(|s| s.wall.penetration(&p_then) > 0.0)
                });
                if let (Some(a), Some(b)) = (behind.next(), behind.next()) {
                    self.corner = Some((a, b));
                }
            }
            if self.samples.len() < self.samples.capacity() {
                self.samples.push(Sample {
                    force: f_mea,
                    position: p_then,
                    velocity: v_then,
                });
                self.force_sum += f_mea;
                if let (Some(sh), Some(m)) = (self.shapes.as_mut(), motion_then) {
                    if sh.motions.len() < sh.motions.capacity() {
                        sh.motions.push(m);
                    }
                }
            }
        }
        if let Some(i) = surface_des {
            self.rendered.get_or_insert(i);
        }
        if let (Some(sh), true) = (self.shapes.as_mut(), shape_des.is_some()) {
            sh.rendered = true;
        }
        // the shapes rendered in this contact: no residual (the planes' model at the robot's
        // pose is not the whole model there)
        let shapes_rendered = self.shapes.as_ref().is_some_and(|sh| sh.rendered);
        if let Some(s) = self.rendered.and_then(|i| self.surfaces[i]) {
            let band = s
                .calibrated
                .map_or(0.0, |c| CALIBRATION_TRUST_SIGMAS * c.sigma_at(&p_then))
                + CALIBRATION_FLOOR;
            self.robot_past = self.robot_past.max(s.wall.penetration(&p_then) - band);
        }

        let applied = match self.mode {
            // free flight as pida has it: the measured force below the detection level passes
            Mode::Free => fallback.applied,
            Mode::Fallback => {
                self.fallback_impulse += fallback.applied.force * self.period;
                fallback.applied
            }
            Mode::Model => {
                let s = self.sensor_origin;
                let f_model = -rod_des; // on the frame
                let f_model_then = -rod_then;
                let residual = if physical && !shapes_rendered {
                    (f_mea - f_model_then) * self.params.residual_gain
                } else {
                    Vector3::zeros()
                };
                // the residual's (and its damping's) work on the virtual motion over the
                // last step, force held: −T·F(k−1)·(v(k−1) + v(k))/2
                if let Some((f_prev, v_prev)) = self.previous {
                    self.residual_energy -= 0.5 * self.period * f_prev.dot(&(v_prev + v_des));
                }
                let base = f_model + residual;
                let direction = if base.norm() > 0.0 {
                    base.normalize()
                } else {
                    Vector3::zeros()
                };
                let along = v_des.dot(&direction);
                let mut damping = Vector3::zeros();
                if self.residual_energy > 0.0 && along.abs() > 0.0 {
                    // F_α = β·(v·e)·e takes T·β·(v·e)² per tick: β for the whole excess,
                    // bounded by force_ratio_max × |F| (the rest waits for the next tick)
                    let wanted = self.residual_energy / (self.period * along * along);
                    let cap = self.params.force_ratio_max
                        * base.norm().max(self.params.fallback.contact_force);
                    let beta = wanted.min(cap / along.abs());
                    damping = direction * (beta * along);
                }
                self.previous = Some((residual + damping, v_des));
                let force = base + damping;
                self.model_impulse += force * self.period;
                // the measured moment that the measured force at the robot's tip does not make
                let unexplained = m_mea - (p_then - s).cross(&f_mea);
                let moment = if physical && !shapes_rendered {
                    unexplained * self.params.residual_gain
                } else {
                    Vector3::zeros()
                };
                let mut wrench = FrameWrench {
                    force,
                    moment: (p_des - s).cross(&force) + moment,
                };
                if let Some(w) = shape_des {
                    // the shapes' wrench as the engine computes it at the virtual pose
                    wrench.force += w.force;
                    wrench.moment += w.moment;
                }
                wrench
            }
        };
        let observed = if self.mode == Mode::Model {
            self.residual_energy
        } else {
            fallback.observed_energy
        };
        // a phantom's impulse taken back by an impulse at the tip: Δv = K·J
        let mut velocity_correction = self
            .undo
            .take()
            .map_or_else(Vector3::zeros, |j| input.tip_mobility * j);
        if let Some((n, speed_in, law, impulse)) = self.restore.take() {
            // the law's change of the normal velocity, −u_in → u_out, against pida's,
            // n·K·(−J): the difference is made up by an impulse j·n at the tip (Δv = K·n·j).
            // Impulses, not velocities, are compared: the normal velocity also drifts in free
            // flight when the bodies turn
            let kn = input.tip_mobility * n;
            let mobility = n.dot(&kn);
            // the account holds where a normal impulse does not turn the bodies (`K·n ∥ n`):
            // there pida's wrench is a force at the tip; elsewhere its moment changes the
            // normal velocity too, and the contact is left as pida made it
            let coupled = (kn - n * mobility).norm() > RESTORE_COUPLING * mobility;
            if mobility > 0.0 && !coupled {
                let ideal = rebound_speed(&law, 1.0 / mobility, speed_in) + speed_in;
                let done = -n.dot(&(input.tip_mobility * impulse));
                // a contact far from the law's (several bounces, the bodies turning much) is
                // beyond this one-dimensional account: left as pida made it
                let error = (ideal - done).abs();
                if error > RESTORE_DEADBAND * ideal && error <= RESTORE_LIMIT * ideal {
                    velocity_correction += input.tip_mobility * n * ((ideal - done) / mobility);
                }
            }
        }
        CompensatorOutput {
            applied,
            velocity_correction,
            estimate: self.estimate().or(fallback.estimate),
            observed_energy: observed,
        }
    }

    fn reset(&mut self) {
        // everything but the parameters and the samples' buffer (no allocation)
        self.fallback.reset();
        self.detector.reset();
        self.kinematics.fill((Vector3::zeros(), Vector3::zeros()));
        self.started = false;
        self.surfaces = self.initial_surfaces;
        self.shared_law = self.initial_law;
        self.shared_friction = self.params.prior_friction;
        self.pending = [None; MAX_SURFACES];
        self.pending_law = None;
        self.pending_friction = None;
        self.samples.clear();
        self.force_sum = Vector3::zeros();
        self.mode = Mode::Free;
        self.physical_ticks = 0;
        self.corner = None;
        self.rendered = None;
        self.residual_energy = 0.0;
        self.previous = None;
        self.since_model = 0;
        self.model_impulse = Vector3::zeros();
        self.undo = None;
        self.robot_past = 0.0;
        self.fallback_impulse = Vector3::zeros();
        self.restore = None;
        self.reason = Rendering::PidaNoPrior;
        self.contradicted = [None; MAX_SURFACES];
        if let Some(sh) = self.shapes.as_mut() {
            sh.reset();
        }
    }

    fn rendering(&self) -> Rendering {
        match self.mode {
            Mode::Free => Rendering::Unreported,
            Mode::Model => Rendering::Model,
            Mode::Fallback => self.reason,
        }
    }

    fn uses_tip_mobility(&self) -> bool {
        true
    }

    fn estimates_contact(&self) -> bool {
        true
    }

    fn observes_energy(&self) -> bool {
        true
    }
}
