//! `dac` — Algorithm 2, damping amendment control: no identification-based correction;
//! `F_act` into the energy observer/controller, `F_act + F_α`, `M_act + M_α` into the
//! dynamics (the identified damping is still used for `F_ek`). See docs/compensators/dac.md.

use super::delay::ContactEstimator;
use super::energy::DampingAmendment;
use super::params::ModelParams;
use super::{Compensator, CompensatorContext, CompensatorInput, CompensatorOutput};

/// Damping amendment control.
#[derive(Debug, Clone)]
pub struct Dac {
    estimator: ContactEstimator,
    amendment: DampingAmendment,
}

impl Dac {
    /// A DAC compensator.
    pub fn new(p: &ModelParams, context: &CompensatorContext) -> Self {
        Dac {
            estimator: ContactEstimator::new(p, context),
            amendment: DampingAmendment::for_robot_force(p, context),
        }
    }
}

impl Compensator for Dac {
    fn step(&mut self, input: &CompensatorInput) -> CompensatorOutput {
        let view = self.estimator.step(input); // steps 1-2
        let alpha = self.amendment.step(&view, &view.force, input); // steps 3-6

        // steps 7-8: F_comp replaced by F_act = (view.force, view.moment) in (29), (30)
        self.amendment
            .output(&view.force, &view.moment, &alpha, &view)
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
