//! `none`: the pass-through compensator. `F_applied = F_mea`, `M_applied = M_mea`.
//! With any delay in the loop the simulation diverges; it is the baseline that shows why
//! compensation is needed.

use super::{Compensator, CompensatorInput, CompensatorOutput};

/// The pass-through compensator (`kind = "none"`).
#[derive(Debug, Clone, Copy, Default)]
pub struct PassThrough;

impl Compensator for PassThrough {
    fn step(&mut self, input: &CompensatorInput) -> CompensatorOutput {
        CompensatorOutput::wrench(input.measured)
    }

    fn reset(&mut self) {}
}
