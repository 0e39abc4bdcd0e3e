//! The facility model, the `[facility] kind = "model"` engine: what stands in for the hardware
//! when nothing external does.
//!
//! - Robot: the actual relative pose follows the commanded one with a pure delay `τ_r`
//!   (commands are interpolated linearly between control ticks, attitude by slerp) and an
//!   optional second-order servo lag `ω_n² / (s² + 2ζω_n s + ω_n²)`, integrated at the plant rate.
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

/// The robot: pure delay plus optional servo lag on the commanded relative motion.
#[derive(Debug, Clone)]
pub struct RobotModel {
    delay_ticks: usize,
    period: f64,
    substeps: u32,
    commands: DelayLine<RelativeMotion>,
    servo: Option<ServoLag>,
    actual: RelativeMotion,
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
            actual: at_rest(initial),
        }
    }

    /// The robot's actual relative motion now.
    pub fn actual(&self) -> &RelativeMotion {
        &self.actual
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
                self.actual = RelativeMotion {
                    position: b.position,
                    orientation: b.orientation,
                    velocity: segment_velocity,
                    angular_velocity: segment_angular_velocity,
                };
            }
            Some(servo) => {
                let h = t / self.substeps as f64;
                let x = &mut self.actual;
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
        );
        let contact = physical_contact(&plan.system, robot.actual(), f.dissipation);
        FacilityModel {
            system: plan.system.clone(),
            robot,
            sensor: SensorModel::new(plan, &contact.wrench),
            contact,
            dissipation: f.dissipation,
        }
    }
}

impl Facility for FacilityModel {
    fn advance(&mut self, command: &RelativeMotion) {
        self.robot.advance(command);
    }

    fn measure(&mut self) -> Measurement {
        self.contact = physical_contact(&self.system, self.robot.actual(), self.dissipation);
        let (force, moment) = self.sensor.sample(&self.contact.wrench);
        Measurement {
            force,
            moment,
            actual: *self.robot.actual(),
        }
    }

    fn contact_force(&self) -> Vector3<f64> {
        self.contact.force
    }

    fn friction_force(&self) -> Vector3<f64> {
        self.contact.friction_force
    }

    fn physical_contact(&self) -> super::PhysicalContact {
        super::PhysicalContact {
            force: self.contact.force,
            friction_force: self.contact.friction_force,
            moment: Some(self.contact.wrench.moment),
        }
    }
}

/// The physical contact for the robot's actual motion, with the facility's added damping
/// `dissipation` (N·s/m) on each pushing contact's normal force, never pulling
/// ([`TwoBodySystem::contact_at`]).
fn physical_contact(system: &TwoBodySystem, actual: &RelativeMotion, dissipation: f64) -> Contact {
    system.contact_at(actual, dissipation)
}
