//! `dac` — Algorithm 2, damping amendment control: no identification-based correction;
//! `F_act` into the energy observer/controller, `F_act + F_α`, `M_act + M_α` into the
//! dynamics (the identified damping is still used for `F_ek`). See docs/compensators/dac.md.

use super::delay::ContactEstimator;
use super::energy::{EnergyController, EnergyObserver};
use super::params::ModelParams;
use super::{Compensator, CompensatorContext, CompensatorInput, CompensatorOutput, ContactEstimate};
use crate::world::FrameWrench;
use nalgebra::Vector3;

/// Damping amendment control.
#[derive(Debug, Clone)]
pub struct Dac {
    estimator: ContactEstimator,
    observer: EnergyObserver,
    controller: EnergyController,
    sensor_origin: Vector3<f64>,
}

impl Dac {
    /// A DAC compensator.
    pub fn new(p: &ModelParams, context: &CompensatorContext) -> Self {
        Dac {
            estimator: ContactEstimator::new(p, context),
            observer: EnergyObserver::new(context.period, p.observer),
            controller: EnergyController::new(context.period, p.alpha_max),
            sensor_origin: context.sensor_origin,
        }
    }
}

impl Compensator for Dac {
    fn step(&mut self, input: &CompensatorInput) -> CompensatorOutput {
        let view = self.estimator.step(input);
        let v = input.tip_velocity_desired;
        let f_ek = self.observer.step(view.in_contact, &view.force, &view.direction, view.damping, &v);
        let (_, f_alpha) = self.controller.step(self.observer.energy(), &f_ek, &view.direction, &v);
        self.observer.record_alpha_force(&f_alpha);
        let m_alpha = (input.tip_position_desired - self.sensor_origin).cross(&f_alpha); // (20)
        CompensatorOutput {
            applied: FrameWrench { force: view.force + f_alpha, moment: view.moment + m_alpha },
            velocity_correction: Vector3::zeros(),
            estimate: Some(ContactEstimate { stiffness: view.stiffness, damping: view.damping }),
            observed_energy: self.observer.energy(),
        }
    }

    fn reset(&mut self) {
        self.estimator.reset();
        self.observer.reset();
    }

    fn estimates_contact(&self) -> bool {
        true
    }

    fn observes_energy(&self) -> bool {
        true
    }
}
