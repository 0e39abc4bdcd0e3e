//! The facility model, the `[facility] kind = "model"` engine: what stands in for the hardware
//! when nothing external does.
//!
//! - Robot: the actual relative pose follows the commanded one with a pure delay `τ_r`
//!   (commands are interpolated linearly between control ticks, attitude by slerp) and an
//!   optional second-order servo lag `ω_n² / (s² + 2ζω_n s + ω_n²)`, integrated at the plant rate.
//! - Repeatability (`facility.robot_repeatability`, σ): where the robot actually goes wanders
//!   from where it believes it is by an Ornstein-Uhlenbeck error of standard deviation σ per
//!   axis (correlation time [`REPEATABILITY_CORRELATION_TIME`]), which it does not report; the
//!   position it reports carries white noise σ per axis (its velocity is reported as tracked).
//! - Contact: the law of [`crate::contact`] between the actual rod tip and the walls.
//! - Sensor: the wrench on the frame from `τ_p` earlier, in the sensor frame, with Gaussian
//!   noise and optional quantisation, from a seeded generator (reproducible runs).
//!
//! [`FacilityModel`] implements [`Facility`]; its [`Facility::advance`] and
//! [`Facility::measure`] never allocate.

use nalgebra::{UnitQuaternion, Vector3};
use rand::SeedableRng;
use rand_distr::{Distribution, StandardNormal};
use rand_pcg::Pcg64Mcg;

use super::{Facility, Measurement};
use crate::delay_line::DelayLine;
use crate::frames::{FrameWrench, RelativeMotion};
use crate::plan::Plan;
use crate::world::{Contact, TwoBodySystem};

/// Second-order servo lag state (`t` frame).
#[derive(Debug, Clone, Copy)]
struct ServoLag {
    /// ω_n, rad/s.
    omega: f64,
    /// ζ.
    zeta: f64,
}

/// Correlation time of the robot's repeatability error, s: the error where the robot goes
/// is nearly constant over a probe's press and independent from one probe to the next.
pub const REPEATABILITY_CORRELATION_TIME: f64 = 1.0;

/// The robot's repeatability: its position error and the noise on what it reports.
#[derive(Debug, Clone)]
struct Repeatability {
    /// σ, m.
    sigma: f64,
    /// The current error of where the robot goes, m (`t`).
    error: Vector3<f64>,
    rng: Pcg64Mcg,
}

impl Repeatability {
    fn gaussian(&mut self) -> Vector3<f64> {
        let rng = &mut self.rng;
        Vector3::from_fn(|_, _| <StandardNormal as Distribution<f64>>::sample(&StandardNormal, rng))
    }
}

/// The robot: pure delay plus optional servo lag on the commanded relative motion, and its
/// repeatability ([`RobotModel::with_repeatability`]).
#[derive(Debug, Clone)]
pub struct RobotModel {
    delay_ticks: usize,
    period: f64,
    substeps: u32,
    commands: DelayLine<RelativeMotion>,
    servo: Option<ServoLag>,
    /// The servo's output (the command followed, without the repeatability error).
    tracked: RelativeMotion,
    /// Where the robot is: `tracked` plus the repeatability error.
    actual: RelativeMotion,
    /// What the robot reports: `tracked` (not the repeatability error) plus the reporting noise.
    reported: RelativeMotion,
    repeatability: Option<Repeatability>,
}

/// Relative motion at rest at a pose.
fn at_rest(pose: &RelativeMotion) -> RelativeMotion {
    RelativeMotion {
        velocity: Vector3::zeros(),
        angular_velocity: Vector3::zeros(),
        ..*pose
    }
}

impl RobotModel {
    /// A robot at rest at the initial command (it held it for all earlier time).
    pub fn new(
        delay_ticks: usize,
        period: f64,
        substeps: u32,
        servo_frequency_hz: f64,
        servo_damping: f64,
        initial: &RelativeMotion,
    ) -> Self {
        let servo = (servo_frequency_hz > 0.0).then_some(ServoLag {
            omega: 2.0 * std::f64::consts::PI * servo_frequency_hz,
            zeta: servo_damping,
        });
        RobotModel {
            delay_ticks,
            period,
            substeps,
            commands: DelayLine::new(delay_ticks + 1, at_rest(initial)),
            servo,
            tracked: at_rest(initial),
            actual: at_rest(initial),
            reported: at_rest(initial),
            repeatability: None,
        }
    }

    /// The same robot with a repeatability of `sigma` (m, standard deviation per axis; 0:
    /// exact) from a generator seeded with `seed`: the error where it goes starts at 0.
    pub fn with_repeatability(mut self, sigma: f64, seed: u64) -> Self {
        self.repeatability = (sigma > 0.0).then(|| Repeatability {
            sigma,
            error: Vector3::zeros(),
            rng: Pcg64Mcg::seed_from_u64(seed),
        });
        self
    }

    /// The robot's actual relative motion now (where it really is).
    pub fn actual(&self) -> &RelativeMotion {
        &self.actual
    }

    /// The relative motion the robot reports now: where its servo took it (its actual motion
    /// without the repeatability error, which it cannot see), plus the noise on the reported
    /// position when it has a repeatability.
    pub fn reported(&self) -> &RelativeMotion {
        &self.reported
    }

    /// Moves the repeatability error one period on and sets `actual` and `reported`.
    fn wander(&mut self) {
        let Some(r) = &mut self.repeatability else {
            self.actual = self.tracked;
            self.reported = self.tracked;
            return;
        };
        // Ornstein-Uhlenbeck, exact discretisation: stationary standard deviation σ
        let a = (-self.period / REPEATABILITY_CORRELATION_TIME).exp();
        let step = r.sigma * (1.0 - a * a).sqrt();
        let kick = r.gaussian();
        r.error = r.error * a + kick * step;
        let noise = r.gaussian() * r.sigma;
        self.actual = RelativeMotion {
            position: self.tracked.position + r.error,
            ..self.tracked
        };
        // the robot believes it is where its servo took it: the error is not reported
        self.reported = RelativeMotion {
            position: self.tracked.position + noise,
            ..self.tracked
        };
    }

    /// Advances one control period after the command for the coming tick was issued.
    pub fn advance(&mut self, command: &RelativeMotion) {
        self.commands.push(*command);
        // the delayed command segment the robot follows during this period
        let a = self.commands.delayed(self.delay_ticks + 1);
        let b = self.commands.delayed(self.delay_ticks);
        let t = self.period;
        let segment_velocity = (b.position - a.position) / t;
        let segment_rotation = a.orientation.inverse() * b.orientation;
        let segment_angular_velocity = a.orientation * segment_rotation.scaled_axis() / t;
        match self.servo {
            None => {
                self.tracked = RelativeMotion {
                    position: b.position,
                    orientation: b.orientation,
                    velocity: segment_velocity,
                    angular_velocity: segment_angular_velocity,
                };
            }
            Some(servo) => {
                let h = t / self.substeps as f64;
                let x = &mut self.tracked;
                for i in 1..=self.substeps {
                    let s = i as f64 / self.substeps as f64;
                    let u_position = a.position.lerp(&b.position, s);
                    let u_orientation = a.orientation.slerp(&b.orientation, s);
                    let w2 = servo.omega * servo.omega;
                    let damp = 2.0 * servo.zeta * servo.omega;
                    // ẍ = ω_n² (u − x) − 2ζω_n ẋ, semi-implicit Euler
                    x.velocity += (w2 * (u_position - x.position) - damp * x.velocity) * h;
                    x.position += x.velocity * h;
                    let attitude_error =
                        x.orientation * (x.orientation.inverse() * u_orientation).scaled_axis();
                    x.angular_velocity += (w2 * attitude_error - damp * x.angular_velocity) * h;
                    x.orientation =
                        UnitQuaternion::from_scaled_axis(x.angular_velocity * h) * x.orientation;
                }
            }
        }
        self.wander();
    }
}

/// The F/T sensor: pure delay, noise, quantisation.
#[derive(Debug, Clone)]
pub struct SensorModel {
    delay_ticks: usize,
    history: DelayLine<FrameWrench>,
    /// Sensor attitude in `t` (sensor to `t`).
    orientation: UnitQuaternion<f64>,
    force_noise: f64,
    torque_noise: f64,
    force_resolution: f64,
    torque_resolution: f64,
    rng: Pcg64Mcg,
}

fn quantise(v: Vector3<f64>, step: f64) -> Vector3<f64> {
    if step > 0.0 {
        v.map(|x| (x / step).round() * step)
    } else {
        v
    }
}

impl SensorModel {
    /// The sensor of a plan (its mounting, [`Plan::sensor`], and the facility model's noise
    /// and resolution), having read `initial` for all earlier time.
    pub fn new(plan: &Plan, initial: &FrameWrench) -> Self {
        let (mount, f) = (&plan.sensor, &plan.facility);
        SensorModel {
            delay_ticks: mount.delay_ticks,
            history: DelayLine::new(mount.delay_ticks, *initial),
            orientation: mount.orientation,
            force_noise: f.force_noise,
            torque_noise: f.torque_noise,
            force_resolution: f.force_resolution,
            torque_resolution: f.torque_resolution,
            rng: Pcg64Mcg::seed_from_u64(f.seed),
        }
    }

    fn noise(&mut self, std: f64) -> Vector3<f64> {
        if std > 0.0 {
            let rng = &mut self.rng;
            Vector3::from_fn(|_, _| {
                std * <StandardNormal as Distribution<f64>>::sample(&StandardNormal, rng)
            })
        } else {
            Vector3::zeros()
        }
    }

    /// Records the physical wrench of this tick (`t` frame) and returns the reading:
    /// the wrench from `τ_p` earlier, in the sensor frame, plus noise, quantised.
    pub fn sample(&mut self, physical: &FrameWrench) -> (Vector3<f64>, Vector3<f64>) {
        self.history.push(*physical);
        let delayed = self.history.delayed(self.delay_ticks);
        let force = self.orientation.inverse_transform_vector(&delayed.force)
            + self.noise(self.force_noise);
        let moment = self.orientation.inverse_transform_vector(&delayed.moment)
            + self.noise(self.torque_noise);
        (
            quantise(force, self.force_resolution),
            quantise(moment, self.torque_resolution),
        )
    }
}

/// Mixed into `facility.seed` for the repeatability's generator (its own stream, apart from
/// the sensor noise's).
const REPEATABILITY_SEED: u64 = 0x7E9E_A7AB_1117_0001;

/// Robot, contact and sensor together: the simulated facility.
#[derive(Debug, Clone)]
pub struct FacilityModel {
    system: TwoBodySystem,
    robot: RobotModel,
    sensor: SensorModel,
    /// The physical contact at the last measurement.
    contact: Contact,
    /// The facility's added contact damping, N·s/m ([`crate::plan::FacilityPlan::dissipation`]).
    dissipation: f64,
    /// Whether the law factor of several shapes' points is measured
    /// ([`Facility::measure_law_factor`]); NaN there otherwise.
    law_factor: bool,
}

impl FacilityModel {
    /// The facility of a plan with the robot at rest at the initial command.
    pub fn new(plan: &Plan, initial_command: &RelativeMotion) -> Self {
        let f = &plan.facility;
        let robot = RobotModel::new(
            f.robot_delay_ticks,
            plan.period,
            plan.plant_substeps,
            f.servo_frequency,
            f.servo_damping,
            initial_command,
        )
        .with_repeatability(f.robot_repeatability, f.seed ^ REPEATABILITY_SEED);
        let contact = physical_contact(&plan.system, robot.actual(), f.dissipation);
        FacilityModel {
            system: plan.system.clone(),
            robot,
            sensor: SensorModel::new(plan, &contact.wrench),
            contact,
            dissipation: f.dissipation,
            law_factor: false,
        }
    }
}

impl Facility for FacilityModel {
    fn advance(&mut self, command: &RelativeMotion) {
        self.robot.advance(command);
    }

    fn measure(&mut self) -> Measurement {
        self.contact = physical_contact(&self.system, self.robot.actual(), self.dissipation);
        if self.law_factor {
            self.contact.law_factor = self
                .system
                .law_factor_at(self.robot.actual(), &self.contact);
        }
        let (force, moment) = self.sensor.sample(&self.contact.wrench);
        Measurement {
            force,
            moment,
            actual: *self.robot.reported(),
        }
    }

    fn contact_force(&self) -> Vector3<f64> {
        self.contact.force
    }

    fn measure_law_factor(&mut self, on: bool) {
        self.law_factor = on;
    }

    fn friction_force(&self) -> Vector3<f64> {
        self.contact.friction_force
    }

    fn physical_contact(&self) -> super::PhysicalContact {
        super::PhysicalContact {
            force: self.contact.force,
            friction_force: self.contact.friction_force,
            moment: Some(self.contact.wrench.moment),
            law_factor: Some(self.contact.law_factor),
        }
    }
}

/// The physical contact for the robot's actual motion, with the facility's added damping
/// `dissipation` (N·s/m) on each pushing contact's normal force, never pulling
/// ([`TwoBodySystem::contact_at`]).
fn physical_contact(system: &TwoBodySystem, actual: &RelativeMotion, dissipation: f64) -> Contact {
    system.contact_at(actual, dissipation)
}
