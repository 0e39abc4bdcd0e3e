//! The time-domain passivity approach (Hannaford & Ryu 2002; Ryu et al. 2005; De Stefano et
//! al. 2020) as baselines. It uses one port between the virtual dynamics and the environment,
//! with power positive into the environment (`f·v`, f the force on the frame).
//!
//! Passivity observer over each exchange with the wall ([`ExchangeWindow`]): it opens when the
//! contact starts, with the work the force did just before while above the quiet level, stays
//! open after the contact while the force is above that level, and carries a deficit left at
//! the close into the next exchange (a surplus is forgotten, so energy banked in one contact
//! cannot come back as a spike in the next). It sums the energy the virtual dynamics actually
//! gave the port over the last step. Under symplectic Euler with the force held, that is
//! `T·f(n−1)·(v(n−1) + v(n))/2`, plus what the controller removed:
//! ```text
//! E(n) = E(n−1) + T·f_applied(n−1)·(v(n−1) + Δv(n−1) + v(n))/2 + (PC dissipation of n−1)
//! impedance type:  α = −E/(T·max(|v|², v_min²)) if E < 0 (α ≤ α_max);  f_applied = f + α·v
//! admittance type: an impulse λ·f/|f| at the rod tip, λ ≥ 0 chosen with the tip's mobility K
//!                  so that it removes exactly −E of kinetic energy; Δv = λ·K·f/|f|
//! ```
//! The measured force is used as it comes (no delay compensation), and neither controller
//! knows the contact's damping: that is the weakness the paper attacks. On a damped contact
//! the real dissipation pays for the energy the delay creates, so rebounds stay too fast.
//! See docs/compensators/tdpa-impedance.md and docs/compensators/tdpa-admittance.md.

use nalgebra::Vector3;

use super::detect::ContactDetector;
use super::energy::ExchangeWindow;
use super::params::TdpaParams;
use super::{Compensator, CompensatorContext, CompensatorInput, CompensatorOutput};
use crate::frames::FrameWrench;

/// The passivity observer over each exchange with the wall ([`ExchangeWindow`]).
#[derive(Debug, Clone, Copy, PartialEq)]
struct PassivityObserver {
    period: f64,
    /// Contact detection (noise-aware, with hysteresis) and the quiet level.
    detector: ContactDetector,
    window: ExchangeWindow,
    /// Force applied and velocity (after the correction) at the previous tick, and the energy
    /// the controller removed there.
    previous: Option<(Vector3<f64>, Vector3<f64>, f64)>,
}

impl PassivityObserver {
    fn new(period: f64, threshold: f64) -> Self {
        PassivityObserver {
            period,
            detector: ContactDetector::new(threshold, period),
            window: ExchangeWindow::default(),
            previous: None,
        }
    }

    fn reset(&mut self) {
        self.window.reset();
        self.detector.reset();
        self.previous = None;
    }

    fn energy(&self) -> f64 {
        self.window.energy()
    }

    /// Adds the last step's port energy; returns whether the window is open (the compensator
    /// applies the force and the controller may act; outside it nothing is applied). Until
    /// [`PassivityObserver::remember`], the applied force is taken to be the measured one.
    fn observe(&mut self, force: &Vector3<f64>, velocity: &Vector3<f64>) -> bool {
        let in_contact = self.detector.update(force);
        let active = force.norm() > self.detector.quiet_threshold();
        let work = self.previous.map_or(0.0, |(f, v, dissipated)| {
            0.5 * self.period * f.dot(&(v + velocity)) + dissipated
        });
        let open = self.window.step(work, in_contact || active);
        let applied = if open { *force } else { Vector3::zeros() };
        self.previous = Some((applied, *velocity, 0.0));
        open
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

/// One tick of a TDPA's observer: observes the measured force and the desired tip velocity
/// and gives the measured wrench as the output to amend, or None outside the observer's window
/// (the force there is the sensor's noise: nothing is applied).
fn observe_tick(
    observer: &mut PassivityObserver,
    input: &CompensatorInput,
) -> Option<CompensatorOutput> {
    observer
        .observe(&input.measured.force, &input.tip_velocity_desired)
        .then(|| CompensatorOutput::wrench(input.measured))
}

impl Compensator for TdpaImpedance {
    fn step(&mut self, input: &CompensatorInput) -> CompensatorOutput {
        let Some(mut out) = observe_tick(&mut self.observer, input) else {
            return CompensatorOutput::wrench(FrameWrench::default()); // the sensor's noise
        };
        let v = input.tip_velocity_desired;
        let (t, e) = (self.observer.period, self.observer.energy());
        let alpha = if e < 0.0 {
            (-e / (t * v.norm_squared().max(self.params.velocity_floor.powi(2))))
                .min(self.params.alpha_max)
        } else {
            0.0
        };
        let f_pc = v * alpha;
        out.applied.force += f_pc;
        out.applied.moment += (input.tip_position_desired - self.sensor_origin).cross(&f_pc);
        out.observed_energy = e;
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

/// Admittance-type TDPA: an impulse at the rod tip, along the measured force, that changes the
/// virtual tip's velocity and removes exactly the deficit.
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

/// The impulse `λ ≥ 0` along the unit vector `u` at a tip of velocity `v` and mobility `κ = uᵀKu`
/// (1/kg) that changes the kinetic energy by `energy` (J, < 0): the smaller root of
/// `λ·u·v + ½κλ² = energy`, real and positive only while `u·v < 0`; where no root is real
/// (the motion along `u` holds less than `−energy`), the `λ` that stops it, `−u·v/κ`.
fn admittance_impulse(energy: f64, uv: f64, kappa: f64) -> f64 {
    if energy >= 0.0 || uv >= 0.0 {
        return 0.0;
    }
    let disc = uv * uv + 2.0 * kappa * energy;
    if disc >= 0.0 {
        (-uv - disc.sqrt()) / kappa
    } else {
        -uv / kappa
    }
}

impl Compensator for TdpaAdmittance {
    fn step(&mut self, input: &CompensatorInput) -> CompensatorOutput {
        let Some(mut out) = observe_tick(&mut self.observer, input) else {
            return CompensatorOutput::wrench(FrameWrench::default()); // the sensor's noise
        };
        let (f, v) = (input.measured.force, input.tip_velocity_desired);
        let e = self.observer.energy();
        out.observed_energy = e;
        let magnitude = f.norm();
        if e >= 0.0 || magnitude < self.params.force_floor {
            return out;
        }
        // the impulse J = λ·u on the servicer at the tip (−J on the target), u along the force
        // on the frame: the tip's velocity changes by λ·K·u and the kinetic energy by exactly
        // λ·u·v + ½κλ²; κ from the virtual dynamics (1/μ where they give none)
        let u = f / magnitude;
        let ku = input.tip_mobility * u;
        let (ku, kappa) = match u.dot(&ku) {
            k if k > 0.0 => (ku, k),
            _ => (u / self.reduced_mass, 1.0 / self.reduced_mass),
        };
        let uv = u.dot(&v);
        // the cap: |Δv| along u at most β_max·|f|, as for a velocity step β·f
        let lambda = admittance_impulse(e, uv, kappa).min(self.params.beta_max * magnitude / kappa);
        let dv = ku * lambda;
        out.velocity_correction = dv;
        let removed = -(lambda * uv + 0.5 * kappa * lambda * lambda);
        self.observer.remember(&f, &(v + dv), removed.max(0.0));
        out
    }

    fn reset(&mut self) {
        self.observer.reset();
    }

    fn observes_energy(&self) -> bool {
        true
    }

    fn uses_tip_mobility(&self) -> bool {
        true
    }
}
