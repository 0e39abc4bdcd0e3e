//! `pida` — Algorithm 3, parameter identification and damping amendment:
//! `F̂_comp = F_comp + F_α` (29), `M̂_comp = M_comp + M_α` (30), with the energy observer fed
//! by `F_comp`. See docs/compensators/pida.md.

use super::delay::ContactEstimator;
use super::energy::DampingAmendment;
use super::force::compensate_force;
use super::params::ModelParams;
use super::{Compensator, CompensatorContext, CompensatorInput, CompensatorOutput};
use nalgebra::Vector3;

/// Parameter identification and damping amendment.
#[derive(Debug, Clone)]
pub struct Pida {
    estimator: ContactEstimator,
    amendment: DampingAmendment,
    sensor_origin: Vector3<f64>,
}

impl Pida {
    /// A PIDA compensator.
    pub fn new(p: &ModelParams, context: &CompensatorContext) -> Self {
        Pida {
            estimator: ContactEstimator::new(p, context),
            amendment: DampingAmendment::new(p, context),
            sensor_origin: context.sensor_origin,
        }
    }
}

impl Compensator for Pida {
    fn step(&mut self, input: &CompensatorInput) -> CompensatorOutput {
        let view = self.estimator.step(input); // steps 1-4
        let comp = compensate_force(&view, input, &self.sensor_origin); // steps 5-6
        let alpha = self.amendment.step(&view, &comp.force, input); // steps 7-10
        self.amendment
            .output(&comp.force, &comp.moment, &alpha, &view) // (29), (30)
    }

    fn reset(&mut self) {
        self.estimator.reset();
        self.amendment.reset();
    }

    fn estimates_contact(&self) -> bool {
        true
    }

    fn observes_energy(&self) -> bool {
        true
    }
}
