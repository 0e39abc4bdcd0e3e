//! The time-domain passivity approach (Hannaford & Ryu 2002; Ryu et al. 2005; De Stefano et
//! al. 2020) as baselines. It uses one port between the virtual dynamics and the environment,
//! with power positive into the environment (`f·v`, f the force on the frame).
//!
//! Passivity observer, windowed to each contact (it restarts when the measured force drops
//! below `contact_force`, so energy banked in one contact cannot come back as a spike in the
//! next). It sums the energy the virtual dynamics actually gave the port over the last step.
//! Under symplectic Euler with the force held, that is `T·f(n−1)·(v(n−1) + v(n))/2`, plus
//! what the controller removed:
//! ```text
//! E(n) = E(n−1) + T·f_applied(n−1)·(v(n−1) + v(n))/2 + (PC dissipation of n−1)
//! impedance type:  α = −E/(T·max(|v|², v_min²)) if E < 0 (α ≤ α_max);  f_applied = f + α·v
//! admittance type: a velocity correction Δv = β·f of the virtual relative motion, β ≥ 0
//!                  chosen so that it removes −E of kinetic energy (β ≤ β_max)
//! ```
//! The measured force is used as it comes (no delay compensation), and neither controller
//! knows the contact's damping: that is the weakness the paper attacks. On a damped contact
//! the real dissipation pays for the energy the delay creates, so rebounds stay too fast.
//! See docs/compensators/tdpa-impedance.md and docs/compensators/tdpa-admittance.md.

use nalgebra::Vector3;

use super::detect::ContactDetector;
use super::params::TdpaParams;
use super::{Compensator, CompensatorContext, CompensatorInput, CompensatorOutput};

/// The passivity observer, restarted at each contact.
#[derive(Debug, Clone, Copy, PartialEq)]
struct PassivityObserver {
    period: f64,
    /// Contact detection (noise-aware, with hysteresis).
    detector: ContactDetector,
    energy: f64,
    /// Force applied and velocity at the previous tick, and the energy the controller removed.
    previous: Option<(Vector3<f64>, Vector3<f64>, f64)>,
}

impl PassivityObserver {
    fn new(period: f64, threshold: f64) -> Self {
        PassivityObserver {
            period,
            detector: ContactDetector::new(threshold, period),
            energy: 0.0,
            previous: None,
        }
    }

    fn reset(&mut self) {
        self.energy = 0.0;
        self.previous = None;
    }

    /// Adds the last step's port energy; returns whether the port is in contact.
    fn observe(&mut self, force: &Vector3<f64>, velocity: &Vector3<f64>) -> bool {
        if !self.detector.update(force) {
            self.reset();
            return false;
        }
        if let Some((f, v, dissipated)) = self.previous {
            self.energy += 0.5 * self.period * f.dot(&(v + velocity)) + dissipated;
        }
        true
    }

    fn remember(&mut self, applied: &Vector3<f64>, velocity: &Vector3<f64>, dissipated: f64) {
        self.previous = Some((*applied, *velocity, dissipated));
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
            observer: PassivityObserver::new(context.period, p.contact_force),
            params: p.clone(),
            sensor_origin: context.sensor_origin,
        }
    }
}

impl Compensator for TdpaImpedance {
    fn step(&mut self, input: &CompensatorInput) -> CompensatorOutput {
        let (f, v) = (input.measured.force, input.tip_velocity_desired);
        let mut out = CompensatorOutput::wrench(input.measured);
        if !self.observer.observe(&f, &v) {
            return out;
        }
        let t = self.observer.period;
        let alpha = if self.observer.energy < 0.0 {
            (-self.observer.energy / (t * v.norm_squared().max(self.params.velocity_floor.powi(2))))
                .min(self.params.alpha_max)
        } else {
            0.0
        };
        let f_pc = v * alpha;
        out.applied.force += f_pc;
        out.applied.moment += (input.tip_position_desired - self.sensor_origin).cross(&f_pc);
        out.observed_energy = self.observer.energy;
        // the damper's work is part of the applied force's work, counted at the next tick
        self.observer.remember(&out.applied.force, &v, 0.0);
        out
    }

    fn reset(&mut self) {
        self.observer.reset();
    }

    fn observes_energy(&self) -> bool {
        true
    }
}

/// Admittance-type TDPA: a damper on the velocity the virtual dynamics output.
#[derive(Debug, Clone)]
pub struct TdpaAdmittance {
    observer: PassivityObserver,
    params: TdpaParams,
    reduced_mass: f64,
}

impl TdpaAdmittance {
    /// An admittance-type passivity controller.
    pub fn new(p: &TdpaParams, context: &CompensatorContext) -> Self {
        TdpaAdmittance {
            observer: PassivityObserver::new(context.period, p.contact_force),
            params: p.clone(),
            reduced_mass: context.reduced_mass,
        }
    }
}

impl Compensator for TdpaAdmittance {
    fn step(&mut self, input: &CompensatorInput) -> CompensatorOutput {
        let (f, v) = (input.measured.force, input.tip_velocity_desired);
        let mut out = CompensatorOutput::wrench(input.measured);
        if !self.observer.observe(&f, &v) {
            return out;
        }
        let (mu, e) = (self.reduced_mass, self.observer.energy);
        let f2 = f.norm_squared().max(self.params.force_floor.powi(2));
        let vf = v.dot(&f);
        // ½μ(|v + βf|² − |v|²) = E: the smaller root, real and positive only when the rod is
        // pushed back (v·f < 0) and E < 0
        let beta = if e < 0.0 && vf < 0.0 {
            let disc = (mu * vf).powi(2) + 2.0 * mu * f2 * e;
            let root = if disc >= 0.0 {
                (-mu * vf - disc.sqrt()) / (mu * f2)
            } else {
                -vf / f2
            };
            root.clamp(0.0, self.params.beta_max)
        } else {
            0.0
        };
        let dv = f * beta;
        out.velocity_correction = dv;
        out.observed_energy = e;
        let removed = -0.5 * mu * ((v + dv).norm_squared() - v.norm_squared());
        self.observer.remember(&f, &(v + dv), removed.max(0.0));
        out
    }

    fn reset(&mut self) {
        self.observer.reset();
    }

    fn observes_energy(&self) -> bool {
        true
    }
}
