//! The time-domain passivity approach (Hannaford & Ryu 2002; Ryu et al. 2005; De Stefano et
//! al. 2020) as baselines. One port between the virtual dynamics and the environment; power
//! positive into the environment (`f·v` with the force on the frame).
//! ```text
//! E(n) = E(n−1) + T·f(n)·v(n) + T·(PC dissipation of n−1)        passivity observer
//! impedance type:  α = −E/(T·max(|v|², v_min²)) if E < 0;  f ← f + α·v   (α ≤ α_max)
//! admittance type: β = −E/(T·max(|f|², f_min²)) if E < 0;  v_cmd ← v + β·f (β ≤ β_max)
//! ```
//! Safeguards: floors on the divisions, caps on α and β, and a windowed observer that restarts
//! at each contact, so energy banked in one contact cannot be released as a spike in the next.
//! The admittance type changes the velocity commanded to the robot, not the virtual state, so the
//! robot's position drifts from the virtual one (a known weakness). See docs/compensators/tdpa.md.

use nalgebra::Vector3;

use super::params::TdpaParams;
use super::{Compensator, CompensatorContext, CompensatorInput, CompensatorOutput};

/// The passivity observer, restarted at each contact.
#[derive(Debug, Clone, Copy, PartialEq)]
struct PassivityObserver {
    period: f64,
    threshold: f64,
    energy: f64,
    previous_dissipation: f64,
}

impl PassivityObserver {
    /// Adds this tick's port energy; returns whether the port is in contact.
    fn observe(&mut self, force: &Vector3<f64>, velocity: &Vector3<f64>) -> bool {
        if force.norm() <= self.threshold {
            self.energy = 0.0;
            self.previous_dissipation = 0.0;
            return false;
        }
        self.energy += self.period * force.dot(velocity) + self.previous_dissipation;
        true
    }
}

/// Impedance-type TDPA: a series damper on the force fed to the dynamics.
#[derive(Debug, Clone)]
pub struct TdpaImpedance {
    observer: PassivityObserver,
    params: TdpaParams,
    sensor_origin: Vector3<f64>,
}

impl TdpaImpedance {
    /// An impedance-type passivity controller.
    pub fn new(p: &TdpaParams, context: &CompensatorContext) -> Self {
        TdpaImpedance {
            observer: PassivityObserver { period: context.period, threshold: p.contact_force, energy: 0.0, previous_dissipation: 0.0 },
            params: p.clone(),
            sensor_origin: context.sensor_origin,
        }
    }
}

impl Compensator for TdpaImpedance {
    fn step(&mut self, input: &CompensatorInput) -> CompensatorOutput {
        let (f, v) = (input.measured.force, input.tip_velocity_desired);
        let in_contact = self.observer.observe(&f, &v);
        let mut out = CompensatorOutput::wrench(input.measured);
        if in_contact {
            let t = self.observer.period;
            let alpha = if self.observer.energy < 0.0 {
                (-self.observer.energy / (t * v.norm_squared().max(self.params.velocity_floor.powi(2)))).min(self.params.alpha_max)
            } else {
                0.0
            };
            let f_pc = v * alpha;
            self.observer.previous_dissipation = t * f_pc.dot(&v);
            out.applied.force += f_pc;
            out.applied.moment += (input.tip_position_desired - self.sensor_origin).cross(&f_pc);
            out.observed_energy = self.observer.energy;
        }
        out
    }

    fn reset(&mut self) {
        self.observer.energy = 0.0;
        self.observer.previous_dissipation = 0.0;
    }

    fn observes_energy(&self) -> bool {
        true
    }
}

/// Admittance-type TDPA: a damper on the velocity commanded to the robot.
#[derive(Debug, Clone)]
pub struct TdpaAdmittance {
    observer: PassivityObserver,
    params: TdpaParams,
}

impl TdpaAdmittance {
    /// An admittance-type passivity controller.
    pub fn new(p: &TdpaParams, context: &CompensatorContext) -> Self {
        TdpaAdmittance {
            observer: PassivityObserver { period: context.period, threshold: p.contact_force, energy: 0.0, previous_dissipation: 0.0 },
            params: p.clone(),
        }
    }
}

impl Compensator for TdpaAdmittance {
    fn step(&mut self, input: &CompensatorInput) -> CompensatorOutput {
        let (f, v) = (input.measured.force, input.tip_velocity_desired);
        let in_contact = self.observer.observe(&f, &v);
        let mut out = CompensatorOutput::wrench(input.measured);
        if in_contact {
            let t = self.observer.period;
            let beta = if self.observer.energy < 0.0 {
                (-self.observer.energy / (t * f.norm_squared().max(self.params.force_floor.powi(2)))).min(self.params.beta_max)
            } else {
                0.0
            };
            out.velocity_correction = f * beta;
            self.observer.previous_dissipation = t * f.dot(&out.velocity_correction);
            out.observed_energy = self.observer.energy;
        }
        out
    }

    fn reset(&mut self) {
        self.observer.energy = 0.0;
        self.observer.previous_dissipation = 0.0;
    }

    fn observes_energy(&self) -> bool {
        true
    }
}
