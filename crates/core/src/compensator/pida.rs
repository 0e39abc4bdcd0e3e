//! `pida` — Algorithm 3, parameter identification and damping amendment:
//! `F̂_comp = F_comp + F_α` (29), `M̂_comp = M_comp + M_α` (30), with the energy observer fed
//! by `F_comp`. See docs/compensators/pida.md.

use super::delay::ContactEstimator;
use super::energy::{EnergyController, EnergyObserver};
use super::force::compensate_force;
use super::params::ModelParams;
use super::{Compensator, CompensatorContext, CompensatorInput, CompensatorOutput, ContactEstimate};
use crate::world::FrameWrench;
use nalgebra::Vector3;

/// Parameter identification and damping amendment.
#[derive(Debug, Clone)]
pub struct Pida {
    estimator: ContactEstimator,
    observer: EnergyObserver,
    controller: EnergyController,
    sensor_origin: Vector3<f64>,
}

impl Pida {
    /// A PIDA compensator.
    pub fn new(p: &ModelParams, context: &CompensatorContext) -> Self {
        Pida {
            estimator: ContactEstimator::new(p, context),
            observer: EnergyObserver::new(context.period, p.observer),
            controller: EnergyController::new(context.period, p.alpha_max),
            sensor_origin: context.sensor_origin,
        }
    }
}

impl Compensator for Pida {
    fn step(&mut self, input: &CompensatorInput) -> CompensatorOutput {
        let view = self.estimator.step(input); // steps 1-4
        let comp = compensate_force(&view, input, &self.sensor_origin); // steps 5-6
        let v = input.tip_velocity_desired;
        let f_ek = self.observer.step(view.in_contact, &comp.force, &view.direction, view.damping, &v); // steps 7-8
        let (_, f_alpha) = self.controller.step(self.observer.energy(), &f_ek, &view.direction, &v); // step 9
        self.observer.record_alpha_force(&f_alpha);
        let m_alpha = (input.tip_position_desired - self.sensor_origin).cross(&f_alpha); // (20)
        CompensatorOutput {
            // (29), (30)
            applied: FrameWrench { force: comp.force + f_alpha, moment: comp.moment + m_alpha },
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
