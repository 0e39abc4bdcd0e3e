//! `none`: the pass-through compensator. `F_applied = F_mea`, `M_applied = M_mea`.
//! With any delay in the loop the simulation diverges; it is the baseline that shows why
//! compensation is needed.

use schemars::JsonSchema;
use serde::{Deserialize, Serialize};

use super::{Compensator, CompensatorContext, CompensatorInput, CompensatorOutput};

/// The pass-through compensator has no parameters (`kind = "none"` and nothing else).
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct NoParams;

/// The pass-through compensator (`kind = "none"`).
#[derive(Debug, Clone, Copy, Default)]
pub struct PassThrough;

impl PassThrough {
    /// The pass-through (it uses neither parameters nor context).
    pub fn new(_params: &NoParams, _context: &CompensatorContext) -> Self {
        PassThrough
    }
}

impl Compensator for PassThrough {
    fn step(&mut self, input: &CompensatorInput) -> CompensatorOutput {
        CompensatorOutput::wrench(input.measured)
    }

    fn reset(&mut self) {}
}
