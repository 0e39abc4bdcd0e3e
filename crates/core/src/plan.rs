//! A scenario resolved once into a validated plan: the only place a scenario is checked.
//!
//! [`Plan::resolve`] checks every value of a [`Scenario`] and reports every problem (not only
//! the first), each naming its dotted key. It produces typed values that cannot be invalid:
//! unit quaternions, unit wall normals, symmetric positive-definite inertia tensors, delays in
//! whole ticks (`facility.round_delays` applied), the compensator's checked parameters. Every
//! physics constructor ([`crate::facility::build`], [`crate::hil::VirtualDynamics`],
//! the reference in [`crate::sim`]) takes the plan and checks nothing again.
//!
//! The sensor as the loop knows it ([`SensorPlan`]: attitude, delay) is kept apart from the
//! facility engine's own parameters ([`FacilityPlan`]), so that the loop reads the same
//! whatever `[facility] kind` stands in for the hardware.
//!
//! The plan also keeps the *resolved scenario* ([`Plan::scenario`]): the input with defaults
//! filled in, quaternions and normals normalised, the inertia symmetrised, wall names set and
//! delays rounded; writing it out and resolving it again gives the same plan.

use std::collections::BTreeSet;

use nalgebra::{Isometry3, Matrix3, Quaternion, Translation3, UnitQuaternion, Vector3};

use crate::body::{BodyState, MassProperties};
use crate::compensator::{CompensatorConfig, PriorShapes, MAX_SURFACES};
use crate::config::{
    BodyConfig, ContactModelKind, FacilityKind, Inertia, Scenario, MAX_NAME_LENGTH, MAX_TICKS,
    MIN_INERTIA,
};
use crate::config::{ShapeConfig, ShapeKind};
use crate::contact::{
    ContactGeometry, ContactModel, Friction, FrictionConfig, HuntCrossley, LinearSpringDamper, Wall,
};
use crate::error::{CoreError, Issues, Result};
use crate::metrics::Tolerances;
use crate::schema::check_ranges;
use crate::shapes::{BodyShape, ShapeGeometry, ShapePairs};
use crate::world::{GeometryPrior, TwoBodyState, TwoBodySystem};

/// The F/T sensor as the HIL loop knows it, whatever stands in for the hardware (a facility
/// engine or the real devices): its attitude on the frame and its delay, which the loop, the
/// compensators, the replay and the identification read. Its origin is the two-body system's
/// `sensor_origin` ([`Plan::system`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SensorPlan {
    /// Sensor attitude in `t` (sensor to `t`).
    pub orientation: UnitQuaternion<f64>,
    /// Sensor delay τ_p in control ticks (known to the compensators).
    pub delay_ticks: usize,
}

/// The facility's engine (`[facility] kind`) and the facility model's own parameters, checked;
/// delays in whole control ticks. Only the engine ([`crate::facility`]) and the metrics'
/// allowance for the facility's lag ([`Plan::facility_lag`]) read them.
#[derive(Debug, Clone, PartialEq)]
pub struct FacilityPlan {
    /// Which engine stands in for the hardware.
    pub kind: FacilityKind,
    /// Robot response delay τ_r in control ticks.
    pub robot_delay_ticks: usize,
    /// Servo lag natural frequency, Hz (0 = no lag).
    pub servo_frequency: f64,
    /// Servo lag damping ratio (> 0).
    pub servo_damping: f64,
    /// Viscous damping the facility adds to the physical contact, N·s/m (0 = none).
    pub dissipation: f64,
    /// Force noise per axis (standard deviation), N.
    pub force_noise: f64,
    /// Moment noise per axis (standard deviation), N·m.
    pub torque_noise: f64,
    /// Force quantisation step, N (0 = none).
    pub force_resolution: f64,
    /// Moment quantisation step, N·m (0 = none).
    pub torque_resolution: f64,
    /// Seed of the sensor-noise generator.
    pub seed: u64,
    /// The robot's repeatability, m (standard deviation of its position error and of the
    /// noise on the position it reports; 0 = exact).
    pub robot_repeatability: f64,
}

/// A validated scenario: everything a run needs, in the types the physics uses.
#[derive(Debug, Clone, PartialEq)]
pub struct Plan {
    /// The resolved scenario (defaults filled in, normalised, delays rounded): what a run
    /// writes out as `scenario.toml`.
    pub scenario: Scenario,
    /// Control period T, s.
    pub period: f64,
    /// Control ticks after the initial one (`duration / period`, rounded).
    pub ticks: usize,
    /// Facility sub-steps per control period (>= 1).
    pub plant_substeps: u32,
    /// RK4 steps per period of the ideal reference in contact (>= 1).
    pub reference_substeps: u32,
    /// A run is diverged once its energy exceeds this many times its bound's base (> 1).
    pub divergence_energy_ratio: f64,
    /// Mass properties, rod, sensor origin, walls and contact law of the *hardware* as it
    /// really is: the scenario's walls mounted at `facility.mount_offset` and
    /// `facility.mount_rotation`, its law scaled by `facility.stiffness_error` and
    /// `facility.damping_error`. The facility model and the ideal reference use it; with the
    /// default facility keys it is [`Plan::nominal`].
    pub system: TwoBodySystem,
    /// The same system as the scenario states it (`[[walls]]`, `[contact]`): what the
    /// compensators, the safety's predicted wrench and `calibrate` know.
    pub nominal: TwoBodySystem,
    /// The initial state of both satellites (world frame).
    pub initial: TwoBodyState,
    /// The F/T sensor's attitude and delay, as the loop knows them.
    pub sensor: SensorPlan,
    /// The facility's engine and the facility model's parameters.
    pub facility: FacilityPlan,
    /// The compensator and its checked parameters.
    pub compensator: CompensatorConfig,
    /// A collision is an interval where the contact force exceeds this, N.
    pub contact_threshold: f64,
    /// When a run that ran to its end is faithful (`[metrics]`).
    pub tolerances: Tolerances,
}

impl Plan {
    /// Checks every value of `scenario` and resolves it; the error lists every problem.
    pub fn resolve(scenario: &Scenario) -> Result<Plan> {
        let mut issues = Issues::default();
        let mut resolved = scenario.clone();
        let r = &mut resolved;

        check_name(&mut issues, &r.name);
        // every number against the range of the schema (`crate::schema`)
        let out_of_range = check_ranges(scenario, &mut issues);
        let failed = &out_of_range;
        let in_range = |key: &str| !out_of_range.contains(key);
        let sim = &r.simulation;
        let period_ok = in_range("simulation.period");
        let duration_ok = in_range("simulation.duration");
        let ticks = if period_ok && duration_ok {
            run_ticks(&mut issues, sim.duration, sim.period)
        } else {
            None
        };

        let servicer = body(&mut issues, failed, "servicer", &mut r.servicer);
        let target = body(&mut issues, failed, "target", &mut r.target);
        finite(&mut issues, failed, "rod.tip", &r.rod.tip);

        let servicer_shapes = body_shapes(&mut issues, failed, "servicer", &mut r.servicer.shapes);
        let target_shapes = body_shapes(&mut issues, failed, "target", &mut r.target.shapes);
        if servicer_shapes.iter().any(|s| s.is_unbounded()) {
            issues.push(
                "servicer.shapes",
                "a half-space can only be a target shape (the mockup's ground)",
            );
        }
        for (i, s) in servicer_shapes.iter().enumerate() {
            if let Some(j) = target_shapes.iter().position(|t| t.is_mesh()) {
                if s.is_mesh() {
                    issues.push(
                        format!("servicer.shapes[{i}]"),
                        format!(
                            "a mesh cannot meet a mesh (target.shapes[{j}]): give one of the two bodies primitives"
                        ),
                    );
                }
            }
        }
        let has_shapes = !servicer_shapes.is_empty() && !target_shapes.is_empty();
        if r.walls.is_empty() && !has_shapes {
            issues.push(
                "walls",
                "at least one [[walls]] table (or shapes on both bodies, [[servicer.shapes]] and [[target.shapes]]) is required",
            );
        }
        let mut walls = Vec::with_capacity(r.walls.len());
        for i in 0..r.walls.len() {
            if r.walls[i].name.is_empty() {
                r.walls[i].name = format!("wall{i}");
            }
            if let Some(j) = r.walls[..i].iter().position(|w| w.name == r.walls[i].name) {
                issues.push(
                    format!("walls[{i}].name"),
                    format!(
                        "duplicate wall name '{}' (also walls[{j}])",
                        r.walls[i].name
                    ),
                );
            }
            let wall = &mut r.walls[i];
            let point_ok = finite(
                &mut issues,
                failed,
                &format!("walls[{i}].point"),
                &wall.point,
            );
            let normal = unit_vector(
                &mut issues,
                failed,
                &format!("walls[{i}].normal"),
                wall.normal,
            );
            if let (true, Some(n)) = (point_ok, normal) {
                wall.normal = n;
                walls.push(Wall {
                    point: Vector3::from(wall.point),
                    normal: Vector3::from(n),
                });
            }
        }

        if let CompensatorConfig::ModelMediated(p) = &mut r.compensator {
            if p.prior_shapes != PriorShapes::None && !has_shapes {
                issues.push(
                    "compensator.prior_shapes",
                    "takes the scenario's shapes as prior geometry: give shapes on both bodies ([[servicer.shapes]] and [[target.shapes]]), or leave it \"none\"",
                );
            }
            if p.prior_walls.len() > MAX_SURFACES {
                issues.push(
                    "compensator.prior_walls",
                    format!(
                        "at most {MAX_SURFACES} prior walls, got {}",
                        p.prior_walls.len()
                    ),
                );
            }
            if !p.calibration.is_empty() {
                if let Err(problems) = p.calibration.check() {
                    for (key, message) in problems {
                        issues.push(format!("compensator.calibration.{key}"), message);
                    }
                }
            }
            for (i, wall) in p.prior_walls.iter_mut().enumerate() {
                if wall.name.is_empty() {
                    wall.name = format!("prior{i}");
                }
                let key = format!("compensator.prior_walls[{i}]");
                finite(&mut issues, failed, &format!("{key}.point"), &wall.point);
                if let Some(n) =
                    unit_vector(&mut issues, failed, &format!("{key}.normal"), wall.normal)
                {
                    wall.normal = n;
                }
            }
        }

        let c = &r.contact;
        let law = ContactModel::new(c.model, c.stiffness, c.damping, c.exponent);

        let friction = c.friction.friction().unwrap_or_else(|message| {
            issues.push("contact.friction.static", message);
            None
        });
        let shape_friction = material_pairs(
            &mut issues,
            &c.friction,
            friction,
            &r.servicer.shapes,
            &r.target.shapes,
        );

        let resolvable = [
            "servicer.mass",
            "target.mass",
            "contact.stiffness",
            "contact.damping",
            "simulation.period",
            "simulation.reference_substeps",
        ]
        .iter()
        .all(|key| in_range(key));
        if resolvable && c.model == ContactModelKind::Linear {
            check_resolution(&mut issues, r);
        }

        let (period, duration) = (r.simulation.period, r.simulation.duration);
        let round = r.facility.round_delays;
        let f = &mut r.facility;
        let mut delay_of = |name: &str, value: &mut f64| {
            let key = format!("facility.{name}");
            let ok = ticks.is_some() && in_range(&key);
            delay(
                &mut issues,
                &key,
                value,
                ok.then_some((period, duration)),
                round,
            )
        };
        let robot_delay_ticks = delay_of("robot_delay", &mut f.robot_delay);
        let sensor_delay_ticks = delay_of("sensor_delay", &mut f.sensor_delay);
        finite(
            &mut issues,
            failed,
            "facility.sensor_position",
            &f.sensor_position,
        );
        let sensor_orientation = unit_quaternion(
            &mut issues,
            failed,
            "facility.sensor_orientation",
            f.sensor_orientation,
        );
        if let Some(q) = sensor_orientation {
            f.sensor_orientation = q;
        }
        finite(
            &mut issues,
            failed,
            "facility.mount_offset",
            &f.mount_offset,
        );
        finite(
            &mut issues,
            failed,
            "facility.mount_rotation",
            &f.mount_rotation,
        );

        issues.finish()?;
        // every check passed, so every part is there
        let (Some(servicer), Some(target), Some(robot), Some(sensor), Some(q), Some(ticks)) = (
            servicer,
            target,
            robot_delay_ticks,
            sensor_delay_ticks,
            sensor_orientation,
            ticks,
        ) else {
            return Err(CoreError::invalid("scenario", "could not be resolved"));
        };
        let f = &resolved.facility;
        let sim = &resolved.simulation;
        let nominal = TwoBodySystem {
            servicer: servicer.0,
            target: target.0,
            rod_tip: Vector3::from(resolved.rod.tip),
            sensor_origin: Vector3::from(f.sensor_position),
            contact: ContactGeometry {
                walls,
                law,
                friction,
                shape_friction,
                shapes: ShapePairs {
                    servicer: servicer_shapes,
                    target: target_shapes,
                },
            },
        };
        let system = TwoBodySystem {
            contact: mounted_hardware(&nominal.contact, f),
            ..nominal.clone()
        };
        let plan = Plan {
            period: sim.period,
            ticks,
            plant_substeps: sim.plant_substeps,
            reference_substeps: sim.reference_substeps,
            divergence_energy_ratio: sim.divergence_energy_ratio,
            system,
            nominal,
            initial: TwoBodyState {
                servicer: servicer.1,
                target: target.1,
            },
            sensor: SensorPlan {
                orientation: to_unit(q),
                delay_ticks: sensor,
            },
            facility: FacilityPlan {
                kind: f.kind,
                robot_delay_ticks: robot,
                servo_frequency: f.servo_frequency,
                servo_damping: f.servo_damping,
                dissipation: f.dissipation,
                force_noise: f.sensor_noise,
                torque_noise: f.torque_noise,
                force_resolution: f.force_resolution,
                torque_resolution: f.torque_resolution,
                seed: f.seed,
                robot_repeatability: f.robot_repeatability,
            },
            compensator: resolved.compensator.clone(),
            contact_threshold: resolved.metrics.contact_threshold,
            tolerances: resolved.metrics.tolerances(),
            scenario: resolved,
        };
        plan.check_shapes_apart()?;
        Ok(plan)
    }

    /// The scenario's nominal geometry as the compensators' prior for a contact's normal
    /// ([`GeometryPrior`], issue 22), when the scenario has friction (`None` when frictionless:
    /// the force's direction is then the normal, and frictionless runs keep their numbers), or
    /// when `model-mediated` renders the shapes as its prior (`compensator.prior_shapes`).
    /// Built from [`Plan::nominal`] only (not the facility's true mounting), the servicer's
    /// initial attitude relative to `t`, a 2 mm wall margin. Allocates once, here.
    pub fn geometry_prior(&self) -> Option<std::sync::Arc<GeometryPrior>> {
        let c = &self.nominal.contact;
        let friction = c
            .friction
            .iter()
            .chain(c.shape_friction.iter().flatten())
            .map(|f| f.kinetic_coefficient.max(f.static_coefficient))
            .fold(0.0, f64::max);
        let shapes_prior = matches!(&self.compensator,
            CompensatorConfig::ModelMediated(p) if p.prior_shapes != PriorShapes::None);
        if (friction <= 0.0 && !shapes_prior) || (c.walls.is_empty() && c.shapes.is_empty()) {
            return None;
        }
        let orientation = self.nominal.relative_motion(&self.initial).orientation;
        Some(std::sync::Arc::new(GeometryPrior {
            system: self.nominal.clone(),
            orientation,
            wall_margin: 2e-3,
            friction,
        }))
    }

    /// Refuses shapes that start interpenetrating: the first pair of shapes in contact at the
    /// initial state, with its penetration.
    fn check_shapes_apart(&self) -> Result<()> {
        let rel = self.system.relative_motion(&self.initial);
        let mut first: Option<crate::shapes::ContactPoint> = None;
        self.system.for_each_shape_contact(&rel, |p| {
            if first.is_none_or(|f| p.depth > f.depth) {
                first = Some(*p);
            }
        });
        match first {
            None => Ok(()),
            Some(p) => {
                let shapes = &self.system.contact.shapes;
                Err(CoreError::invalid(
                    format!("servicer.shapes[{}]", p.servicer_shape),
                    format!(
                        "'{}' and target.shapes[{}] '{}' start interpenetrating ({:.4} mm deep at [{:.4}, {:.4}, {:.4}] m in the target frame): move the bodies apart",
                        shapes.servicer[p.servicer_shape].name,
                        p.target_shape,
                        shapes.target[p.target_shape].name,
                        p.depth * 1e3,
                        p.point.x,
                        p.point.y,
                        p.point.z
                    ),
                ))
            }
        }
    }

    /// The sensor delay τ_p, s (whole ticks).
    pub fn sensor_delay(&self) -> f64 {
        self.sensor.delay_ticks as f64 * self.period
    }

    /// The facility's lag, s: the robot delay τ_r plus, with a servo lag, its time constant
    /// 2ζ/ω_n (the lag of a second-order servo behind a ramp).
    pub fn facility_lag(&self) -> f64 {
        let f = &self.facility;
        let servo = if f.servo_frequency > 0.0 {
            2.0 * f.servo_damping / (2.0 * std::f64::consts::PI * f.servo_frequency)
        } else {
            0.0
        };
        self.robot_delay() + servo
    }

    /// The undamped contact frequency of a linear contact, Hz: `√(k/μ) / 2π` with the reduced
    /// mass `μ = m_s m_t / (m_s + m_t)`; `None` for a Hunt-Crossley contact.
    pub fn contact_frequency(&self) -> Option<f64> {
        match self.system.contact.law {
            ContactModel::Linear(l) => Some(
                (l.stiffness / self.system.reduced_mass()).sqrt() / (2.0 * std::f64::consts::PI),
            ),
            ContactModel::HuntCrossley(_) => None,
        }
    }

    /// The robot delay τ_r, s (whole ticks).
    pub fn robot_delay(&self) -> f64 {
        self.facility.robot_delay_ticks as f64 * self.period
    }

    /// The scenario's name.
    pub fn name(&self) -> &str {
        &self.scenario.name
    }
}

impl Scenario {
    /// Resolves the scenario into a validated [`Plan`] (see [`Plan::resolve`]).
    pub fn resolve(&self) -> Result<Plan> {
        Plan::resolve(self)
    }
}

/// The hardware's contact geometry as the facility has it: the scenario's `nominal` geometry
/// mounted at [`mount_pose`], its law's stiffness and damping scaled by
/// `facility.stiffness_error` and `facility.damping_error`. The default keys give `nominal`
/// itself, bit for bit.
pub fn mounted_hardware(
    nominal: &ContactGeometry,
    f: &crate::config::FacilityConfig,
) -> ContactGeometry {
    let mut hardware = if f.mount_offset == [0.0; 3] && f.mount_rotation == [0.0; 3] {
        nominal.clone()
    } else {
        let pose = mount_pose(nominal, f);
        nominal.mounted(&pose)
    };
    let (ks, cs) = (f.stiffness_error, f.damping_error);
    if ks != 1.0 || cs != 1.0 {
        hardware.law = match hardware.law {
            ContactModel::Linear(l) => ContactModel::Linear(LinearSpringDamper {
                stiffness: l.stiffness * ks,
                damping: l.damping * cs,
            }),
            ContactModel::HuntCrossley(h) => ContactModel::HuntCrossley(HuntCrossley {
                stiffness: h.stiffness * ks,
                damping: h.damping * cs,
                exponent: h.exponent,
            }),
        };
    }
    hardware
}

/// The hardware's mounting against its nominal pose (`t` frame): the rotation
/// `facility.mount_rotation` (a rotation vector, degrees) about the centre of the walls'
/// points (the mockup; without walls, of the target's shapes' origins), then the offset
/// `facility.mount_offset` (m).
pub fn mount_pose(
    nominal: &ContactGeometry,
    f: &crate::config::FacilityConfig,
) -> nalgebra::Isometry3<f64> {
    // the centre of the walls' points, or without walls of the target's shapes' origins
    let points: Vec<Vector3<f64>> = if nominal.walls.is_empty() {
        let shapes = &nominal.shapes.target;
        shapes.iter().map(|s| s.pose.translation.vector).collect()
    } else {
        nominal.walls.iter().map(|w| w.point).collect()
    };
    let n = points.len().max(1) as f64;
    let centre = points.iter().fold(Vector3::zeros(), |c, p| c + p / n);
    let rotation = nalgebra::UnitQuaternion::from_scaled_axis(
        Vector3::from(f.mount_rotation).map(f64::to_radians),
    );
    nalgebra::Isometry3::from_parts(
        nalgebra::Translation3::from(centre + Vector3::from(f.mount_offset) - rotation * centre),
        rotation,
    )
}

/// `x` with 12 significant digits, as the scenario files and messages show numbers
/// (`13 × 0.001` is `0.013`).
pub fn g12(x: f64) -> f64 {
    format!("{x:.11e}").parse().unwrap_or(x)
}

/// `x` for a message: [`g12`], in exponent form when very small or large (`1e-320`, not 320
/// zeros).
fn show(x: f64) -> String {
    let x = g12(x);
    if x != 0.0 && !(1e-4..1e15).contains(&x.abs()) {
        format!("{x:e}")
    } else {
        format!("{x}")
    }
}

/// A name that is a valid folder name everywhere: 1 to [`MAX_NAME_LENGTH`] characters, not
/// `.` or `..`, without `/`, `\\` or control characters (NUL included).
fn check_name(issues: &mut Issues, name: &str) {
    let trimmed = name.trim();
    let length = name.chars().count();
    if trimmed.is_empty()
        || trimmed == "."
        || trimmed == ".."
        || length > MAX_NAME_LENGTH
        || name.contains('/')
        || name.contains('\\')
        || name.chars().any(char::is_control)
    {
        let shown: String = name.chars().take(40).collect();
        let shown = if length > 40 {
            format!("{shown:?}... ({length} characters)")
        } else {
            format!("{shown:?}")
        };
        issues.push(
            "name",
            format!(
                "must be 1 to {MAX_NAME_LENGTH} characters without '/', '\\' or control characters, not '.' or '..' (it names the output folder), got {shown}"
            ),
        );
    }
}

/// The run's control ticks after the initial one, `duration / period` rounded, checked: a
/// duration of at least one period, at most [`MAX_TICKS`] ticks.
fn run_ticks(issues: &mut Issues, duration: f64, period: f64) -> Option<usize> {
    let ratio = (duration / period).round();
    if !(duration >= period) {
        issues.push(
            "simulation.duration",
            format!(
                "{} s is shorter than one period (simulation.period = {} s)",
                show(duration),
                show(period)
            ),
        );
        return None;
    }
    if !(ratio <= MAX_TICKS) {
        issues.push(
            "simulation.duration",
            format!(
                "{} s at simulation.period = {} s is {ratio:e} control periods; at most {MAX_TICKS:e} are allowed",
                show(duration),
                show(period)
            ),
        );
        return None;
    }
    Some(ratio as usize)
}

/// A linear contact that the ideal reference's RK4 steps (`simulation.period /
/// simulation.reference_substeps`) resolve: `ω·h <= 1` with `ω = √(k/μ)` (μ the reduced mass),
/// and `(c/μ)·h <= 2`. A stiffer contact would make the reference, and so every metric,
/// meaningless or non-finite.
fn check_resolution(issues: &mut Issues, s: &Scenario) {
    let (ms, mt) = (s.servicer.mass, s.target.mass);
    let mu = ms * mt / (ms + mt);
    let h = s.simulation.period / f64::from(s.simulation.reference_substeps);
    let (k, c) = (s.contact.stiffness, s.contact.damping);
    let omega = (k / mu).sqrt();
    let step = format!(
        "simulation.period / simulation.reference_substeps = {} s",
        show(h)
    );
    if omega * h > 1.0 {
        let hz = |w: f64| show(w / (2.0 * std::f64::consts::PI));
        issues.push(
            "contact.stiffness",
            format!(
                "{} N/m with the reduced mass {} kg is a contact frequency of {} Hz, above the {} Hz the ideal reference resolves with {step}: lower it, or raise simulation.reference_substeps",
                show(k),
                show(mu),
                hz(omega),
                hz(1.0 / h)
            ),
        );
    } else if c / mu * h > 2.0 {
        issues.push(
            "contact.damping",
            format!(
                "{} N·s/m with the reduced mass {} kg damps faster than the ideal reference resolves with {step} (c/μ·h <= 2): lower it, or raise simulation.reference_substeps",
                show(c),
                show(mu)
            ),
        );
    }
}

/// Whether every number of `v` is finite; records the problem unless `key` failed its range
/// check already (`failed`, which reported it).
fn finite(issues: &mut Issues, failed: &BTreeSet<String>, key: &str, v: &[f64]) -> bool {
    if failed.contains(key) {
        return false;
    }
    let ok = v.iter().all(|x| x.is_finite());
    if !ok {
        issues.push(key, format!("must contain finite numbers, got {v:?}"));
    }
    ok
}

/// `v / |v|`, keeping a vector that is already of unit norm (to 1e-12) bit for bit, so that
/// resolving a resolved scenario changes nothing.
fn normalised<const N: usize>(v: [f64; N], norm: f64) -> [f64; N] {
    if (norm - 1.0).abs() <= 1e-12 {
        v
    } else {
        v.map(|x| x / norm)
    }
}

fn unit_vector(
    issues: &mut Issues,
    failed: &BTreeSet<String>,
    key: &str,
    v: [f64; 3],
) -> Option<[f64; 3]> {
    if !finite(issues, failed, key, &v) {
        return None;
    }
    let norm = Vector3::from(v).norm();
    if norm < 1e-12 {
        issues.push(
            key,
            format!("must be a nonzero vector (it is normalised), got {v:?}"),
        );
        return None;
    }
    Some(normalised(v, norm))
}

fn quaternion_norm(q: &[f64; 4]) -> f64 {
    Quaternion::new(q[0], q[1], q[2], q[3]).norm()
}

/// A unit quaternion `[w, x, y, z]` from a nonzero finite one.
fn unit_quaternion(
    issues: &mut Issues,
    failed: &BTreeSet<String>,
    key: &str,
    q: [f64; 4],
) -> Option<[f64; 4]> {
    if !finite(issues, failed, key, &q) {
        return None;
    }
    let norm = quaternion_norm(&q);
    if norm < 1e-12 {
        issues.push(
            key,
            format!("must be a nonzero quaternion [w, x, y, z] (it is normalised), got {q:?}"),
        );
        return None;
    }
    Some(normalised(q, norm))
}

/// The unit quaternion of a resolved `[w, x, y, z]`.
fn to_unit(q: [f64; 4]) -> UnitQuaternion<f64> {
    UnitQuaternion::new_normalize(Quaternion::new(q[0], q[1], q[2], q[3]))
}

/// The inertia as a symmetric positive-definite tensor (symmetrised exactly), or a problem.
fn inertia(
    issues: &mut Issues,
    failed: &BTreeSet<String>,
    key: &str,
    inertia: &Inertia,
) -> Option<Matrix3<f64>> {
    let rows = match *inertia {
        Inertia::Principal(d) => {
            if !finite(issues, failed, key, &d) {
                return None;
            }
            if d.iter().any(|&m| m < MIN_INERTIA) {
                issues.push(
                    key,
                    format!("principal moments must all be >= {MIN_INERTIA:e}, got {d:?}"),
                );
                return None;
            }
            [[d[0], 0.0, 0.0], [0.0, d[1], 0.0], [0.0, 0.0, d[2]]]
        }
        Inertia::Tensor(rows) => rows,
    };
    if !finite(issues, failed, key, &rows.concat()) {
        return None;
    }
    let m = Matrix3::from_fn(|i, j| rows[i][j]);
    let scale = m.abs().max();
    if (m - m.transpose()).abs().max() > 1e-9 * scale {
        issues.push(
            key,
            format!("the 3x3 matrix must be symmetric, got {rows:?}"),
        );
        return None;
    }
    let symmetric = Matrix3::from_fn(|i, j| {
        if i == j {
            m[(i, i)]
        } else {
            0.5 * (m[(i, j)] + m[(j, i)])
        }
    });
    let smallest = symmetric.symmetric_eigenvalues().min();
    if symmetric.cholesky().is_none() || !(smallest >= MIN_INERTIA) {
        issues.push(
            key,
            format!(
                "the 3x3 matrix must be positive definite with principal moments >= {MIN_INERTIA:e}, got {rows:?}"
            ),
        );
        return None;
    }
    Some(symmetric)
}

/// The mass properties and initial state of a body; normalises its orientation and
/// symmetrises its inertia in `config`.
fn body(
    issues: &mut Issues,
    failed: &BTreeSet<String>,
    key: &str,
    config: &mut BodyConfig,
) -> Option<(MassProperties, BodyState)> {
    let tensor = inertia(issues, failed, &format!("{key}.inertia"), &config.inertia);
    let q = unit_quaternion(
        issues,
        failed,
        &format!("{key}.orientation"),
        config.orientation,
    );
    let vectors_ok = [
        ("position", config.position),
        ("velocity", config.velocity),
        ("angular_velocity", config.angular_velocity),
    ]
    .iter()
    .fold(true, |ok, (name, v)| {
        finite(issues, failed, &format!("{key}.{name}"), v) && ok
    });
    let (Some(tensor), Some(q), true) = (tensor, q, vectors_ok) else {
        return None;
    };
    // the resolved inertia is always the full tensor (principal moments on its diagonal)
    config.inertia = Inertia::Tensor([0, 1, 2].map(|i| [0, 1, 2].map(|j| tensor[(i, j)])));
    config.orientation = q;
    Some((
        MassProperties::new(config.mass, tensor),
        BodyState {
            position: Vector3::from(config.position),
            orientation: to_unit(q),
            velocity: Vector3::from(config.velocity),
            angular_velocity: Vector3::from(config.angular_velocity),
        },
    ))
}

/// A delay in whole periods: `key` (s, in its range) rounded to the nearest period if `round`,
/// else rejected unless it is a whole number of periods (a positive delay below half a period
/// included); longer than the run's `duration` rejected. Written back as the whole periods
/// it runs as. Nothing without a valid `(period, duration)`.
fn delay(
    issues: &mut Issues,
    key: &str,
    delay: &mut f64,
    run: Option<(f64, f64)>,
    round: bool,
) -> Option<usize> {
    let (period, duration) = run?;
    if *delay > duration {
        issues.push(
            key,
            format!(
                "{} s is longer than the run (simulation.duration = {} s)",
                show(*delay),
                show(duration)
            ),
        );
        return None;
    }
    let ratio = *delay / period;
    let n = (ratio + 0.5).floor();
    let whole = (ratio - n).abs() <= 1e-9 * ratio.max(1.0) && (n > 0.0 || *delay == 0.0);
    if !round && !whole {
        let lo = ratio.floor();
        issues.push(
            key,
            format!(
                "{} s is not a whole number of periods (simulation.period = {} s): use {} or {}, or set facility.round_delays = true",
                show(*delay),
                show(period),
                show(lo * period),
                show((lo + 1.0) * period)
            ),
        );
        return None;
    }
    // within [0, duration / period] <= MAX_TICKS (checked by `run_ticks` and above)
    if !(n >= 0.0 && n <= MAX_TICKS) {
        issues.push(key, format!("{} s is not a usable delay", show(*delay)));
        return None;
    }
    *delay = g12(n * period);
    Some(n as usize)
}

/// The shapes of a body (`key`: `servicer` or `target`), checked; names set (`{kind}{i}`) in
/// the resolved scenario. A shape with a problem is recorded and left out.
/// The friction of every pair of shapes (servicer shape `a`, target shape `b` at
/// `a·target.len() + b`) from `[[contact.friction.pairs]]`: a listed pair of materials takes
/// its coefficients, any other pair `default`. Empty when no pair is listed (every contact has
/// `default`). Refuses a pair without shapes on both bodies, an empty or unused material name,
/// a pair listed twice and a static coefficient below the kinetic one.
fn material_pairs(
    issues: &mut Issues,
    table: &FrictionConfig,
    default: Option<Friction>,
    servicer: &[ShapeConfig],
    target: &[ShapeConfig],
) -> Vec<Option<Friction>> {
    if table.pairs.is_empty() {
        return Vec::new();
    }
    if servicer.is_empty() || target.is_empty() {
        issues.push(
            "contact.friction.pairs",
            "friction per material pair needs shapes on both bodies ([[servicer.shapes]] and \
             [[target.shapes]] with `material` names)",
        );
        return Vec::new();
    }
    let used: BTreeSet<&str> = servicer
        .iter()
        .chain(target)
        .map(|s| s.material.as_str())
        .filter(|m| !m.is_empty())
        .collect();
    let mut laws = Vec::with_capacity(table.pairs.len());
    for (i, pair) in table.pairs.iter().enumerate() {
        let key = format!("contact.friction.pairs[{i}]");
        for m in &pair.materials {
            if m.trim().is_empty() {
                issues.push(
                    format!("{key}.materials"),
                    "a material name must not be empty",
                );
            } else if !used.contains(m.as_str()) {
                let known: Vec<&str> = used.iter().copied().collect();
                issues.push(
                    format!("{key}.materials"),
                    format!(
                        "no shape has material '{m}' (the shapes' materials: {})",
                        if known.is_empty() {
                            "none given".to_string()
                        } else {
                            known.join(", ")
                        }
                    ),
                );
            }
        }
        let same = |q: &crate::contact::MaterialPairFriction| {
            let [a, b] = &pair.materials;
            let [c, d] = &q.materials;
            (a == c && b == d) || (a == d && b == c)
        };
        if let Some(j) = table.pairs[..i].iter().position(same) {
            issues.push(
                format!("{key}.materials"),
                format!("the pair is listed twice (also contact.friction.pairs[{j}])"),
            );
        }
        laws.push(table.pair_friction(i).unwrap_or_else(|message| {
            issues.push(format!("{key}.static"), message);
            None
        }));
    }
    let mut out = Vec::with_capacity(servicer.len() * target.len());
    for s in servicer {
        for t in target {
            let listed = table.pairs.iter().position(|p| {
                let [a, b] = &p.materials;
                (*a == s.material && *b == t.material) || (*a == t.material && *b == s.material)
            });
            out.push(listed.map_or(default, |i| laws[i]));
        }
    }
    out
}

fn body_shapes(
    issues: &mut Issues,
    failed: &BTreeSet<String>,
    key: &str,
    shapes: &mut [ShapeConfig],
) -> Vec<BodyShape> {
    let mut out = Vec::with_capacity(shapes.len());
    for i in 0..shapes.len() {
        let k = format!("{key}.shapes[{i}]");
        if shapes[i].name.is_empty() {
            let kind = serde_json::to_value(shapes[i].kind)
                .ok()
                .and_then(|v| v.as_str().map(str::to_string))
                .unwrap_or_default();
            shapes[i].name = format!("{kind}{i}");
        }
        if let Some(j) = shapes[..i].iter().position(|s| s.name == shapes[i].name) {
            issues.push(
                format!("{k}.name"),
                format!(
                    "duplicate shape name '{}' (also {key}.shapes[{j}])",
                    shapes[i].name
                ),
            );
        }
        let c = &mut shapes[i];
        let position_ok = finite(issues, failed, &format!("{k}.position"), &c.position);
        let q = unit_quaternion(issues, failed, &format!("{k}.orientation"), c.orientation);
        if let Some(q) = q {
            c.orientation = q;
        }
        let Some(geometry) = shape_geometry(issues, failed, &k, c) else {
            continue;
        };
        let (true, Some(q)) = (position_ok, q) else {
            continue;
        };
        let mut rotation = to_unit(q);
        if c.kind == ShapeKind::HalfSpace {
            // the plane's normal is the shape frame's z axis
            let n = Vector3::from(c.normal);
            rotation = UnitQuaternion::rotation_between(&Vector3::z(), &n).unwrap_or_else(|| {
                UnitQuaternion::from_axis_angle(&Vector3::x_axis(), std::f64::consts::PI)
            });
        }
        let pose = Isometry3::from_parts(Translation3::from(Vector3::from(c.position)), rotation);
        out.push(BodyShape::new(c.name.clone(), geometry, pose));
    }
    out
}

/// A shape's geometry from its keys, checked for its kind (`key`: the shape's dotted key).
fn shape_geometry(
    issues: &mut Issues,
    failed: &BTreeSet<String>,
    key: &str,
    c: &mut ShapeConfig,
) -> Option<ShapeGeometry> {
    let bad = |k: &str| failed.contains(&format!("{key}.{k}"));
    if ["radius", "length", "margin", "size", "scale"]
        .iter()
        .any(|k| bad(k))
    {
        return None;
    }
    let positive = |issues: &mut Issues, name: &str, x: f64| {
        if x > 0.0 {
            true
        } else {
            issues.push(
                format!("{key}.{name}"),
                format!("must be > 0 for a {:?} shape, got {x}", c.kind).to_lowercase(),
            );
            false
        }
    };
    let margin_below = |issues: &mut Issues, limit: f64| {
        if c.margin < limit {
            true
        } else {
            issues.push(
                format!("{key}.margin"),
                format!(
                    "must be below half the shape's smallest dimension ({limit}), got {}",
                    c.margin
                ),
            );
            false
        }
    };
    match c.kind {
        ShapeKind::Sphere => positive(issues, "radius", c.radius)
            .then_some(ShapeGeometry::Sphere { radius: c.radius }),
        ShapeKind::Box => {
            let ok = positive(
                issues,
                "size",
                c.size.iter().copied().fold(f64::INFINITY, f64::min),
            );
            let smallest = c.size.iter().copied().fold(f64::INFINITY, f64::min);
            (ok && margin_below(issues, 0.5 * smallest)).then_some(ShapeGeometry::Box {
                size: c.size,
                margin: c.margin,
            })
        }
        ShapeKind::Cylinder | ShapeKind::Cone => {
            let ok = positive(issues, "radius", c.radius) & positive(issues, "length", c.length);
            (ok && margin_below(issues, c.radius.min(0.5 * c.length))).then(|| {
                if c.kind == ShapeKind::Cylinder {
                    ShapeGeometry::Cylinder {
                        radius: c.radius,
                        length: c.length,
                        margin: c.margin,
                    }
                } else {
                    ShapeGeometry::Cone {
                        radius: c.radius,
                        length: c.length,
                        margin: c.margin,
                    }
                }
            })
        }
        ShapeKind::Capsule => {
            positive(issues, "radius", c.radius).then_some(ShapeGeometry::Capsule {
                radius: c.radius,
                length: c.length,
            })
        }
        ShapeKind::HalfSpace => {
            let n = unit_vector(issues, failed, &format!("{key}.normal"), c.normal)?;
            c.normal = n;
            Some(ShapeGeometry::HalfSpace)
        }
        ShapeKind::Mesh => mesh(issues, key, c),
    }
}

/// A mesh's vertices (times `scale`) and triangles, checked: not empty, finite, indices in
/// range, no degenerate triangle, no edge shared by more than two triangles (non-manifold).
fn mesh(issues: &mut Issues, key: &str, c: &ShapeConfig) -> Option<ShapeGeometry> {
    let source = if c.file.is_empty() {
        String::new()
    } else {
        format!(" (file {})", c.file)
    };
    if c.vertices.is_empty() || c.triangles.is_empty() {
        issues.push(
            key,
            format!(
                "the mesh is empty: {} vertices, {} triangles{source}",
                c.vertices.len(),
                c.triangles.len()
            ),
        );
        return None;
    }
    if let Some(i) = c
        .vertices
        .iter()
        .position(|v| v.iter().any(|x| !x.is_finite()))
    {
        issues.push(
            format!("{key}.vertices[{i}]"),
            format!(
                "must contain finite numbers, got {:?}{source}",
                c.vertices[i]
            ),
        );
        return None;
    }
    let n = c.vertices.len();
    let vertices: Vec<[f64; 3]> = c.vertices.iter().map(|v| v.map(|x| x * c.scale)).collect();
    let mut edges = std::collections::HashMap::<(u32, u32), u32>::new();
    for (i, t) in c.triangles.iter().enumerate() {
        if let Some(&bad) = t.iter().find(|&&v| v as usize >= n) {
            issues.push(
                format!("{key}.triangles[{i}]"),
                format!("vertex index {bad} out of range (the mesh has {n} vertices){source}"),
            );
            return None;
        }
        let p = t.map(|v| Vector3::from(vertices[v as usize]));
        let area = 0.5 * (p[1] - p[0]).cross(&(p[2] - p[0])).norm();
        let scale = (p[1] - p[0]).norm().max((p[2] - p[0]).norm()).max(1e-300);
        if area <= 1e-12 * scale * scale {
            issues.push(
                format!("{key}.triangles[{i}]"),
                format!("degenerate triangle {t:?} (zero area){source}"),
            );
            return None;
        }
        for (a, b) in [(t[0], t[1]), (t[1], t[2]), (t[2], t[0])] {
            let count = edges.entry((a.min(b), a.max(b))).or_insert(0);
            *count += 1;
            if *count > 2 {
                issues.push(
                    format!("{key}.triangles[{i}]"),
                    format!(
                        "non-manifold mesh: the edge between vertices {a} and {b} belongs to more than two triangles{source}"
                    ),
                );
                return None;
            }
        }
    }
    Some(ShapeGeometry::Mesh {
        vertices,
        triangles: c.triangles.clone(),
    })
}
