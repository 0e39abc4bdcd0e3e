//! The scenario as data: the schema of a scenario file (names, types, defaults, units), as
//! serde reads it from TOML or JSON. Nothing here is checked: [`crate::plan::Plan::resolve`]
//! turns a scenario into a validated plan once, and every physics constructor takes the plan.
//!
//! Field names are the scenario file's keys (`docs/scenario.md`); all values are SI.

use schemars::JsonSchema;
use serde::{Deserialize, Serialize};

use crate::compensator::CompensatorConfig;
pub use crate::contact::{ContactModelKind, WallConfig};
use crate::metrics::Tolerances;

/// Longest scenario name, characters (it names the output folder).
pub const MAX_NAME_LENGTH: usize = 100;
/// Smallest principal moment of inertia, kg·m² (of a principal moment, or the smallest
/// eigenvalue of a tensor).
pub const MIN_INERTIA: f64 = 1e-6;
/// Most control ticks of a run (`simulation.duration / simulation.period`): past it the core
/// refuses the scenario rather than allocate its records.
pub const MAX_TICKS: f64 = 1e9;

/// A complete scenario: two satellites, the collision geometry, the contact, the facility,
/// the compensator and the metric settings.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct Scenario {
    /// Short name (used for the output folder): 1 to 100 characters, not `.` or `..`, without
    /// `/`, `\\` or control characters.
    #[schemars(length(min = 1, max = MAX_NAME_LENGTH))]
    pub name: String,
    /// One line for humans.
    #[serde(default)]
    pub description: String,
    /// Time stepping.
    pub simulation: SimulationConfig,
    /// The servicer satellite, which carries the rod.
    pub servicer: BodyConfig,
    /// The target satellite, which carries the walls; its body frame is the mockup frame `t`.
    pub target: BodyConfig,
    /// The rod on the servicer.
    pub rod: RodConfig,
    /// Planar walls fixed in the target frame, met by the rod tip (at least one wall, or
    /// shapes on both bodies).
    #[serde(default)]
    pub walls: Vec<WallConfig>,
    /// Contact law between the rod tip and the walls.
    pub contact: ContactConfig,
    /// The facility: its engine (`kind`), robot response and sensor.
    #[serde(default)]
    pub facility: FacilityConfig,
    /// Delay compensator.
    #[serde(default)]
    pub compensator: CompensatorConfig,
    /// Metric settings.
    #[serde(default)]
    pub metrics: MetricsConfig,
}

/// Time stepping of the loop.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct SimulationConfig {
    /// Simulated duration, s (> 0, at most a day).
    #[schemars(extend("exclusiveMinimum" = 0.0), range(max = 86400.0))]
    pub duration: f64,
    /// Control period T in s, 1 µs to 1 s.
    #[schemars(range(min = 1e-6, max = 1.0))]
    pub period: f64,
    /// Facility sub-steps per control period (1 to 1000).
    #[serde(default = "default_substeps")]
    #[schemars(range(min = 1, max = 1000))]
    pub plant_substeps: u32,
    /// RK4 steps per control period for the ideal reference while in contact (1 to 1000);
    /// free flight takes one step per period.
    #[serde(default = "default_reference_substeps")]
    #[schemars(range(min = 1, max = 1000))]
    pub reference_substeps: u32,
    /// The run is `diverged` once its energy exceeds this many times the larger of the
    /// initial energy and the reference's largest energy (> 1, <= 1e12).
    #[serde(default = "default_divergence_ratio")]
    #[schemars(extend("exclusiveMinimum" = 1.0), range(max = 1e12))]
    pub divergence_energy_ratio: f64,
}

fn default_substeps() -> u32 {
    10
}
fn default_reference_substeps() -> u32 {
    2
}
fn default_divergence_ratio() -> f64 {
    100.0
}

/// A free-floating rigid body: mass properties and initial state (world frame).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct BodyConfig {
    /// kg, 0.001 to 1e7.
    #[schemars(range(min = 1e-3, max = 1e7))]
    pub mass: f64,
    /// Inertia about the centre of mass in the body frame, kg·m²: principal moments or a
    /// symmetric positive-definite tensor (every moment >= 1e-6, every entry |I| <= 1e10).
    #[schemars(extend("x-magnitude" = 1e10))]
    pub inertia: Inertia,
    /// Initial centre-of-mass position, m (world frame).
    #[serde(default)]
    #[schemars(extend("x-value" = "vec3", "x-magnitude" = 1e3))]
    pub position: [f64; 3],
    /// Initial attitude, unit quaternion [w, x, y, z], body to world.
    #[serde(default = "identity_quaternion")]
    #[schemars(extend("x-value" = "quaternion", "x-magnitude" = 1e6))]
    pub orientation: [f64; 4],
    /// Initial centre-of-mass velocity, m/s (world frame).
    #[serde(default)]
    #[schemars(extend("x-value" = "vec3", "x-magnitude" = 1e3))]
    pub velocity: [f64; 3],
    /// Initial angular velocity, rad/s (body frame).
    #[serde(default)]
    #[schemars(extend("x-value" = "vec3", "x-magnitude" = 1e3))]
    pub angular_velocity: [f64; 3],
    /// Collision shapes fixed in the body (`[[servicer.shapes]]`, `[[target.shapes]]`): every
    /// servicer shape meets every target shape, besides the rod tip against the walls.
    #[serde(default)]
    #[schemars(length(max = 64))]
    pub shapes: Vec<ShapeConfig>,
}

/// What a collision shape is.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, JsonSchema)]
#[serde(rename_all = "kebab-case")]
pub enum ShapeKind {
    /// A sphere: `radius`.
    Sphere,
    /// A box: `size` (full edge lengths), edges rounded by `margin`.
    Box,
    /// A cylinder along the shape's z axis: `radius`, `length`, edges rounded by `margin`.
    Cylinder,
    /// A capsule along z: `radius`, `length` between the centres of its end caps.
    Capsule,
    /// A cone along z: base `radius` at z = −length/2, apex at +length/2, rounded by `margin`.
    Cone,
    /// A half-space (target only): the plane through `position` with outward `normal`.
    HalfSpace,
    /// A triangle mesh from `file` (STL or OBJ, relative to the scenario file), times `scale`.
    Mesh,
}

/// A collision shape in its body's frame. Which keys a kind reads: sphere `radius`; box `size`,
/// `margin`; cylinder and cone `radius`, `length`, `margin`; capsule `radius`, `length`;
/// half-space `normal`; mesh `file`, `scale` (or `vertices` and `triangles`). Every kind:
/// `position`, `orientation`, `material`, `name`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct ShapeConfig {
    /// Name for reports. Default: the kind and its index (`box2`).
    #[serde(default)]
    pub name: String,
    /// What the shape is.
    pub kind: ShapeKind,
    /// Radius, m (sphere, capsule, cylinder; the cone's base), 0 to 100.
    #[serde(default)]
    #[schemars(range(min = 0.0, max = 100.0))]
    pub radius: f64,
    /// Length along the shape's z axis, m (cylinder, cone; the capsule's between its cap
    /// centres), 0 to 100.
    #[serde(default)]
    #[schemars(range(min = 0.0, max = 100.0))]
    pub length: f64,
    /// Full edge lengths of a box along x, y, z, m.
    #[serde(default)]
    #[schemars(extend("x-value" = "vec3", "x-magnitude" = 100.0))]
    pub size: [f64; 3],
    /// Edge rounding of a box, cylinder or cone, m (0 to 0.1; below half its smallest
    /// dimension): its edges and corners are rounded by it, its outer size unchanged.
    #[serde(default = "default_margin")]
    #[schemars(range(min = 0.0, max = 0.1))]
    pub margin: f64,
    /// The shape's origin in the body frame, m (the centre of a box, sphere, cylinder, capsule
    /// or cone; a point of a half-space's plane; a mesh's origin).
    #[serde(default)]
    #[schemars(extend("x-value" = "vec3", "x-magnitude" = 1e3))]
    pub position: [f64; 3],
    /// The shape's attitude in the body frame, unit quaternion [w, x, y, z] (shape to body).
    #[serde(default = "identity_quaternion")]
    #[schemars(extend("x-value" = "quaternion", "x-magnitude" = 1e6))]
    pub orientation: [f64; 4],
    /// Normal from the plane into free space: a half-space's, body frame (normalised).
    #[serde(default)]
    #[schemars(extend("x-value" = "vec3", "x-magnitude" = 1e6))]
    pub normal: [f64; 3],
    /// Material name: `[[contact.friction.pairs]]` gives friction per pair of materials.
    #[serde(default)]
    pub material: String,
    /// A mesh's file, STL or OBJ, relative to the scenario file (read by the scenario loader,
    /// which fills `vertices` and `triangles`).
    #[serde(default)]
    pub file: String,
    /// A mesh file's length unit in m (0.001 for a CAD file in mm), > 0, <= 1000.
    #[serde(default = "default_scale")]
    #[schemars(extend("exclusiveMinimum" = 0.0), range(max = 1000.0))]
    pub scale: f64,
    /// A mesh's vertices in the shape frame, m (after `scale`).
    #[serde(default)]
    pub vertices: Vec<[f64; 3]>,
    /// A mesh's triangles, vertex indices from 0.
    #[serde(default)]
    pub triangles: Vec<[u32; 3]>,
}

fn default_margin() -> f64 {
    0.0005
}

fn default_scale() -> f64 {
    1.0
}

/// An inertia given as principal moments `[Ixx, Iyy, Izz]` or as a full 3×3 tensor, kg·m².
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(untagged)]
#[schemars(extend("x-value" = "inertia"))]
pub enum Inertia {
    /// Principal moments (a diagonal tensor).
    Principal([f64; 3]),
    /// Full tensor, rows.
    Tensor([[f64; 3]; 3]),
}

fn identity_quaternion() -> [f64; 4] {
    [1.0, 0.0, 0.0, 0.0]
}

/// The rod carried by the servicer.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct RodConfig {
    /// Rod tip (the contact point) in the servicer body frame, m.
    #[schemars(extend("x-value" = "vec3", "x-magnitude" = 1e3))]
    pub tip: [f64; 3],
}

/// Contact law parameters.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct ContactConfig {
    /// Contact law.
    #[serde(default)]
    pub model: ContactModelKind,
    /// Stiffness k: N/m (linear) or N/m^n (Hunt-Crossley), > 0, <= 1e11.
    #[schemars(extend("exclusiveMinimum" = 0.0), range(max = 1e11))]
    pub stiffness: f64,
    /// Damping c: N·s/m (linear) or N·s/m^(n+1) (Hunt-Crossley), 0 to 1e9.
    #[serde(default)]
    #[schemars(range(min = 0.0, max = 1e9))]
    pub damping: f64,
    /// Hunt-Crossley exponent n (> 0, <= 5); unused by the linear law.
    #[serde(default = "default_exponent")]
    #[schemars(extend("exclusiveMinimum" = 0.0), range(max = 5.0))]
    pub exponent: f64,
    /// Coulomb friction between the contacting surfaces (default: frictionless).
    #[serde(default)]
    pub friction: crate::contact::FrictionConfig,
}

fn default_exponent() -> f64 {
    1.5
}

/// Which engine stands in for the hardware (robot, mockup, F/T sensor) in a simulation and in
/// the emulated facility.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, Default, JsonSchema)]
#[serde(rename_all = "kebab-case")]
pub enum FacilityKind {
    /// The facility model: robot delay and servo lag, the contact law with the walls, sensor
    /// delay, noise and quantisation (the keys of `[facility]`).
    #[default]
    Model,
    /// MuJoCo (the `mujoco` Python package): the rod touches the mockup in a MuJoCo model
    /// (`facility.mujoco_model`, or one written from the scenario), the robot and the sensor
    /// as the facility model's. A Python engine: `hilcontact` (Python) runs it through
    /// `hilcontact._core.simulate_facility`; the core alone cannot build it
    /// ([`crate::facility::build`] refuses it).
    Mujoco,
}

/// The facility: which engine stands in for the hardware, the facility model's robot response
/// and F/T sensor, and the sensor's mounting on the frame.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct FacilityConfig {
    /// Pure delay of the robot's response, s (a whole number of periods, 0 to 60, at most
    /// the run's duration).
    #[serde(default)]
    #[schemars(range(min = 0.0, max = 60.0))]
    pub robot_delay: f64,
    /// Pure delay of the sensor, s (a whole number of periods, 0 to 60, at most the run's
    /// duration).
    #[serde(default)]
    #[schemars(range(min = 0.0, max = 60.0))]
    pub sensor_delay: f64,
    /// Natural frequency of the robot's second-order servo lag, Hz (0 = no lag, <= 1e4).
    #[serde(default)]
    #[schemars(range(min = 0.0, max = 1e4))]
    pub servo_frequency: f64,
    /// Damping ratio of the servo lag (> 0, <= 100).
    #[serde(default = "default_servo_damping")]
    #[schemars(extend("exclusiveMinimum" = 0.0), range(max = 100.0))]
    pub servo_damping: f64,
    /// Viscous damping the facility adds to the physical contact (its mounts and the robot's
    /// compliance), N·s/m (0 = none, the default; <= 1e9): the measured contact force grows
    /// by `d·v_n` against the rod tip's approach and shrinks by it on the rebound (`v_n`: the
    /// tip's speed along the force), never pulling. The ideal reference does not have it.
    #[serde(default)]
    #[schemars(range(min = 0.0, max = 1e9))]
    pub dissipation: f64,
    /// Gaussian noise on each force axis, N (standard deviation, 0 to 1e6).
    #[serde(default)]
    #[schemars(range(min = 0.0, max = 1e6))]
    pub sensor_noise: f64,
    /// Gaussian noise on each moment axis, N·m (standard deviation, 0 to 1e6).
    #[serde(default)]
    #[schemars(range(min = 0.0, max = 1e6))]
    pub torque_noise: f64,
    /// Force quantisation step, N (0 = none, else 1e-9 to 1e6).
    #[serde(default)]
    #[schemars(range(min = 0.0, max = 1e6), extend("x-nonzero-minimum" = 1e-9))]
    pub force_resolution: f64,
    /// Moment quantisation step, N·m (0 = none, else 1e-9 to 1e6).
    #[serde(default)]
    #[schemars(range(min = 0.0, max = 1e6), extend("x-nonzero-minimum" = 1e-9))]
    pub torque_resolution: f64,
    /// Sensor origin in the target frame, m.
    #[serde(default)]
    #[schemars(extend("x-value" = "vec3", "x-magnitude" = 1e3))]
    pub sensor_position: [f64; 3],
    /// Sensor attitude in the target frame, unit quaternion [w, x, y, z] (sensor to target).
    #[serde(default = "identity_quaternion")]
    #[schemars(extend("x-value" = "quaternion", "x-magnitude" = 1e6))]
    pub sensor_orientation: [f64; 4],
    /// Seed of the sensor-noise generator (integer, 0 to 2^64 - 1).
    #[serde(default)]
    pub seed: u64,
    /// Round delays to whole periods instead of rejecting them (the Python layer applies it).
    #[serde(default)]
    pub round_delays: bool,
    /// Which engine stands in for the hardware: `"model"` (the facility model, the default; the
    /// keys above are its parameters and the sensor's mounting) or `"mujoco"` (MuJoCo for the
    /// contact, docs/mujoco.md; the robot and sensor keys above apply as well).
    #[serde(default)]
    pub kind: FacilityKind,
    /// `kind = "mujoco"`: an MJCF file of the hardware, relative to the scenario file (empty,
    /// the default: the model is written from the scenario's bodies, rod and walls).
    #[serde(default)]
    pub mujoco_model: String,
    /// `kind = "mujoco"` and the MuJoCo cross-check: MuJoCo's integration step, s (1e-7 to
    /// 1e-2; default 1e-4).
    #[serde(default = "default_mujoco_timestep")]
    #[schemars(range(min = 1e-7, max = 1e-2))]
    pub mujoco_timestep: f64,
    /// The hardware mounted off its nominal pose: offset of the target's contact geometry
    /// against the scenario's `[[walls]]`, m (`t` frame; applied after `mount_rotation`; zeros,
    /// the default: mounted as the scenario says). The facility and the ideal reference use
    /// the mounted geometry; compensators, the safety's predicted wrench and `calibrate` know
    /// only the scenario's.
    #[serde(default)]
    #[schemars(extend("x-value" = "vec3", "x-magnitude" = 1.0))]
    pub mount_offset: [f64; 3],
    /// The hardware's mounting rotation against its nominal pose, a rotation vector in degrees
    /// (axis × angle, `t` frame, about the centre of the walls' points, applied before
    /// `mount_offset`; zeros,
    /// the default: none; each component |x| ≤ 90).
    #[serde(default)]
    #[schemars(extend("x-value" = "vec3", "x-magnitude" = 90.0))]
    pub mount_rotation: [f64; 3],
    /// The robot's repeatability, m (standard deviation, 0 to 0.01; 0, the default: exact):
    /// where the robot actually goes wanders from where it believes it is by a slowly varying
    /// error of this size (per axis, correlation time 1 s) that it does not report, and the
    /// position it reports carries white noise of this size (per axis).
    #[serde(default)]
    #[schemars(range(min = 0.0, max = 0.01))]
    pub robot_repeatability: f64,
    /// The real contact's stiffness against the scenario's `contact.stiffness`, a factor (> 0,
    /// <= 100; 1, the default: as stated). The facility and the ideal reference use
    /// `stiffness_error × contact.stiffness`; compensators know only the scenario's value.
    #[serde(default = "unit_factor")]
    #[schemars(extend("exclusiveMinimum" = 0.0), range(max = 100.0))]
    pub stiffness_error: f64,
    /// The real contact's damping against the scenario's `contact.damping`, a factor (0 to 100;
    /// 1, the default: as stated), like `stiffness_error`.
    #[serde(default = "unit_factor")]
    #[schemars(range(min = 0.0, max = 100.0))]
    pub damping_error: f64,
}

fn default_mujoco_timestep() -> f64 {
    1e-4
}

fn unit_factor() -> f64 {
    1.0
}

fn default_servo_damping() -> f64 {
    0.7
}

impl Default for FacilityConfig {
    fn default() -> Self {
        FacilityConfig {
            robot_delay: 0.0,
            sensor_delay: 0.0,
            servo_frequency: 0.0,
            servo_damping: default_servo_damping(),
            dissipation: 0.0,
            sensor_noise: 0.0,
            torque_noise: 0.0,
            force_resolution: 0.0,
            torque_resolution: 0.0,
            sensor_position: [0.0; 3],
            sensor_orientation: identity_quaternion(),
            seed: 0,
            round_delays: false,
            kind: FacilityKind::Model,
            mujoco_model: String::new(),
            mujoco_timestep: default_mujoco_timestep(),
            mount_offset: [0.0; 3],
            mount_rotation: [0.0; 3],
            robot_repeatability: 0.0,
            stiffness_error: 1.0,
            damping_error: 1.0,
        }
    }
}

/// Metric settings.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct MetricsConfig {
    /// A collision is an interval where the physical contact force exceeds this, N (> 0,
    /// <= 1e9).
    #[serde(default = "default_contact_threshold")]
    #[schemars(extend("exclusiveMinimum" = 0.0), range(max = 1e9))]
    pub contact_threshold: f64,
    /// Largest `|CoV − 1|` of a faithful collision (fraction, 0 to 1e6).
    #[serde(default = "default_cov_tolerance")]
    #[schemars(range(min = 0.0, max = 1e6))]
    pub cov_tolerance: f64,
    /// Largest CoF of a faithful collision (> 0, <= 1e6).
    #[serde(default = "default_max_cof")]
    #[schemars(extend("exclusiveMinimum" = 0.0), range(max = 1e6))]
    pub max_cof: f64,
    /// Largest rebound velocity error `|v − v_ref| / |v_ref|` of a faithful collision
    /// (fraction, 0 to 1e6).
    #[serde(default = "default_max_velocity_error")]
    #[schemars(range(min = 0.0, max = 1e6))]
    pub max_velocity_error: f64,
    /// Largest tangential impulse error `|J_t − J_t,ref| / max(|J_t,ref|, 0.01 |J_n,ref|)` of a
    /// faithful collision (fraction, 0 to 1e6; docs/model.md "Metrics").
    #[serde(default = "default_max_tangential_impulse_error")]
    #[schemars(range(min = 0.0, max = 1e6))]
    pub max_tangential_impulse_error: f64,
    /// How many reference collisions a faithful run may lose (integer, 0 to 1e6).
    #[serde(default)]
    #[schemars(range(max = 1000000))]
    pub max_lost_collisions: u32,
    /// How many collisions without a reference collision a faithful run may have (integer,
    /// 0 to 1e6).
    #[serde(default)]
    #[schemars(range(max = 1000000))]
    pub max_extra_collisions: u32,
    /// The first collision the verdict judges (1-based, integer 1 to 1e6; default 1, every
    /// collision): earlier ones are reported but not judged, e.g. 3 to judge `model-mediated`
    /// from each wall's second contact on `paper-table1`. Lost and extra collisions always count.
    #[serde(default = "default_judge_from")]
    #[schemars(range(min = 1, max = 1000000))]
    pub judge_from: u32,
    /// Whether each collision is also compared with its local reference, the ideal reference
    /// restarted from the virtual state before it (the `local_*` errors, docs/model.md
    /// "Metrics"; read, never judged). Off by default: the restarts cost a simulated run 5-25 %.
    #[serde(default)]
    pub local_references: bool,
}

fn default_judge_from() -> u32 {
    1
}

fn default_contact_threshold() -> f64 {
    0.5
}
fn default_cov_tolerance() -> f64 {
    Tolerances::default().cov
}
fn default_max_cof() -> f64 {
    Tolerances::default().cof
}
fn default_max_velocity_error() -> f64 {
    Tolerances::default().velocity_error
}
fn default_max_tangential_impulse_error() -> f64 {
    Tolerances::default().tangential_impulse_error
}

impl MetricsConfig {
    /// The tolerances of the verdict.
    pub fn tolerances(&self) -> Tolerances {
        Tolerances {
            cov: self.cov_tolerance,
            cof: self.max_cof,
            velocity_error: self.max_velocity_error,
            tangential_impulse_error: self.max_tangential_impulse_error,
            lost_collisions: self.max_lost_collisions as usize,
            extra_collisions: self.max_extra_collisions as usize,
            judge_from: self.judge_from as usize,
        }
    }
}

impl Default for MetricsConfig {
    fn default() -> Self {
        MetricsConfig {
            contact_threshold: default_contact_threshold(),
            cov_tolerance: default_cov_tolerance(),
            max_cof: default_max_cof(),
            max_velocity_error: default_max_velocity_error(),
            max_tangential_impulse_error: default_max_tangential_impulse_error(),
            max_lost_collisions: 0,
            max_extra_collisions: 0,
            judge_from: default_judge_from(),
            local_references: false,
        }
    }
}
