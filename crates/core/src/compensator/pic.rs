//! `pic` — Algorithm 1, parameter identification control: `F_comp`, `M_comp` (eqs. 22, 28)
//! straight into the dynamics. See docs/compensators/pic.md.

use super::delay::ContactEstimator;
use super::force::{compensate_force, compensate_force_pulling};
use super::params::ModelParams;
use super::{
    Compensator, CompensatorContext, CompensatorInput, CompensatorOutput, ContactEstimate,
};
use crate::frames::FrameWrench;
use nalgebra::Vector3;

/// Parameter identification control.
#[derive(Debug, Clone)]
pub struct Pic {
    estimator: ContactEstimator,
    sensor_origin: Vector3<f64>,
    /// Eq. (22) unclamped ([`ModelParams::pull`]).
    pull: bool,
}

impl Pic {
    /// A PIC compensator.
    pub fn new(p: &ModelParams, context: &CompensatorContext) -> Self {
        Pic {
            estimator: ContactEstimator::new(p, context),
            sensor_origin: context.sensor_origin,
            pull: p.pull,
        }
    }
}

impl Compensator for Pic {
    fn step(&mut self, input: &CompensatorInput) -> CompensatorOutput {
        let view = self.estimator.step(input); // steps 1-4
        let comp = if self.pull {
            compensate_force_pulling(&view, input, &self.sensor_origin) // steps 5-6, eq. (22) as written
        } else {
            compensate_force(&view, input, &self.sensor_origin) // steps 5-6
        };
        CompensatorOutput {
            applied: FrameWrench {
                force: comp.force,
                moment: comp.moment,
            }, // step 7
            estimate: Some(ContactEstimate {
                stiffness: view.stiffness,
                damping: view.damping,
            }),
            ..CompensatorOutput::wrench(FrameWrench::default())
        }
    }

    fn reset(&mut self) {
        self.estimator.reset();
    }

    fn estimates_contact(&self) -> bool {
        true
    }
}
